"""Response models (they drive the OpenAPI docs)."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, Field


class Verification(BaseModel):
    """Re-simulation of a trial that became best, at a finer step or in another engine (not_checked, pending,
    holds, moved, judged, diverged; older run files: not_reproduced). A judged set ranks by its judged
    distance; a diverged (or not-reproduced) one never counts as best."""

    verdict: str
    # "holds" (same engine, within the robot's chaos floor), "moved 5.2% at the finer step", "judged in bullet"
    label: str | None = None
    fine_step_distance_m: float | None
    screen_distance_m: float | None = None
    judge_distance_m: float | None = None
    screen_to_judge_ratio: float | None = None
    reason: str | None
    judge: str | None = None  # how it was re-simulated: "bullet at 0.25 ms", or a finer step of the same engine
    counted_distance_m: float | None = Field(None, description="the distance that counts: the judge's when it "
                                             "judged the set, else the screen's")
    judged_speed_cm_s: float | None = Field(None, description="a judged set's speed: the judged distance over "
                                            "the simulated time (null for a set not judged)")


class Audit(BaseModel):
    """Re-simulation by another worker at the same fidelity (not_audited, pending, agrees, disagrees)."""

    state: str
    distance_m: float | None = None
    worker_id: str | None = None
    note: str | None = Field(None, description="why a pending audit has not run: \"unaudited (no other worker "
                             "identity)\" when the run ended with no worker of another identity to run it")


class SpreadSide(BaseModel):
    """One engine's run of a judged best (an evaluation row)."""

    engine: str
    dt_s: float | None = Field(None, description="the step it ran at (s)")
    distance_m: float | None
    cot: float | None = Field(None, description="the cost of transport it measured (null: not measured, a run "
                              "file of schema 8, or the judge's side read from the verdict's columns)")
    status: str | None = Field(None, description="complete or failed (null: from the verdict's columns)")
    reason: str | None = None
    wall_time_s: float | None = None
    worker_id: str | None = None


class ModelSpread(BaseModel):
    """A judged best in both engines (storage.model_spread): the judge's run and the other engine's second
    opinion (an evaluation of kind "opinion"), their ratio beside each engine's step error."""

    judge: SpreadSide
    other: SpreadSide = Field(description="the engine that does not judge, at a converged step")
    ratio: float | None = Field(description="other / judge distance (null when either is missing or failed)")
    step_error: dict[str, float | None] = Field(description="per engine, the median relative change of a "
                                                "gait's distance at half the step, from the run's calibration "
                                                "(empty: the run was not calibrated)")


class Trial(BaseModel):
    trial_id: int
    status: str
    reason: str
    phase: str
    parent: int | None
    seed: int
    objective: float | None
    scores: dict[str, float | None]
    params: dict[str, float]
    params_unit: dict[str, float]
    worker_id: str | None
    finished_at_unix_s: float | None
    verification: Verification
    audit: Audit | None = None
    pareto_front: bool
    engine: str | None = None        # the engine and step this trial actually ran with
    dt_s: float | None = None
    settle_s: float | None = None
    rung: int = 0                    # multi-fidelity rung (0: the screen)
    duration_s: float | None = None  # simulated duration asked for (null: the run's)
    judged_cot: float | None = Field(None, description="a judged set's cost of transport in the judge's run "
                                     "(/best, /trials/ID and the run's best; null: not judged, or see "
                                     "judged_cot_note); scores.cot is the screen's")
    judged_cot_note: str | None = Field(None, description="why a judged set has no judged_cot: \"not measured "
                                        "(...)\" in a run file from before the judge's COT was stored")
    model_spread: ModelSpread | None = Field(None, description="a judged best's distance in the other engine "
                                             "too (/best and /trials/ID only; null: no second opinion stored)")



class TrialPage(BaseModel):
    """GET /runs/{run_id}/trials: trials in id order, `offset` and `limit` into those of `status` (all if null)."""

    run_id: str
    status: str | None
    total: int = Field(description="trials of that status in the run (the page is a slice of them)")
    offset: int
    limit: int
    trials: list[Trial]

class Ladder(BaseModel):
    """The rungs a run screens with and why (`search --engine auto` stores its reason with the ladder it adds)."""

    rungs: str = Field(description="the rungs' trial lengths in s, as --rungs takes them, e.g. \"0.5,1.5,3\"")
    eta: int = Field(description="the halving scheduler keeps the best 1/eta of each rung")
    reason: str | None = Field(description="why this ladder: the robot's own (its spec file named), the default, "
                               "\"--eta N given\", or \"typed (--rungs)\"; null: auto added it before the reason "
                               "was stored")
    engine_auto: bool = Field(description="`search --engine auto` added this ladder (else the rungs were typed)")


class Worker(BaseModel):
    worker_id: str
    alive: bool
    leases: int
    last_contact_unix_s: float
    engines: list[str] | None = None
    environment: dict[str, str] = Field(default_factory=dict, description="python, packages, CPU it reported")
    audits_agree: int = 0
    audits_disagree: int = 0
    quarantined: bool = False
    session: str | None = Field(None, description="the Zenoh session its identity queryable answered from (its "
                                "identity for audits); empty: it did not answer")


class RunStatus(BaseModel):
    run_id: str
    file: str
    morphology: str
    objective: str
    state: str = Field(description="running, stalled (its coordinator holds the file but is silent), done, "
                       "stopped (budget not met, no coordinator: resumable), failed, or empty; from the file")
    trials_budget: int = Field(description="parameter sets the run samples")
    trials_planned: int = Field(description="evaluations it expects: the budget, plus a multi-fidelity run's "
                                "promotions to longer trials")
    parameter_sets_sampled: int
    file_schema_version: int | None = Field(None, description="the schema the run file was written at")
    file_note: str | None = Field(None, description="what an older run file lacks (null for a current one)")
    parameter_sets_done: int | None = Field(None, description="parameter sets whose first evaluation finished")
    evaluations_done: int | None = Field(None, description="every finished simulation of any set: screen rungs, "
                                         "judge runs, audits and referees")
    best_distance_m: float | None = Field(None, description="the best set's distance that counts (judged when "
                                          "the judge ran it)")
    trials_done: int = Field(description="trial rows finished (complete or failed)")
    trials_complete: int
    trials_failed: int
    trials_leased: int | None
    trials_queued: int | None
    rate_trials_s: float | None
    eta_s: float | None
    best: Trial | None = Field(description="the best set; with auditing on, the best one another worker identity's "
                               "audit agreed with")
    pending_audit: Trial | None = Field(None, description="with auditing on: a set better than the best whose "
                                        "audit has not agreed yet (not the best until it does)")
    workers: list[Worker]
    status_age_s: float | None
    status_file_error: str | None = Field(None, description="why the run's status file (RUN.h5.status.json) "
                                          "was set aside; the state then comes from the run file alone")
    started_at_unix_s: float | None = None
    controller: str | None = None
    engine: str | None = Field(None, description="the engine of every trial (null: a test objective)")
    step_s: float | None = Field(None, description="the physics step the trials ran with (median)")
    sampler: str | None = None
    rungs_s: list[float] | None = Field(None, description="a multi-fidelity run's trial lengths, short to full")
    ladder: Ladder | None = Field(None, description="a multi-fidelity run's screening ladder and why it is this "
                                  "one (null: a run of one length)")
    reopen_command: str = Field(description="the command that serves this run file again")
    resume_command: str | None = Field(None, description="the command that continues a stopped run")
    audit: dict[str, Any] | None = Field(None, description="audits_pending/agrees/disagrees/quarantined, fraction, "
                                         "tolerance, the figures per worker environment, and comparisons: how many "
                                         "audits demanded the same bits (exact) or the tolerance, and "
                                         "unaudited: trial id -> why its audit stays pending")
    claimed_by: dict[str, str] = Field(default_factory=dict, description="other coordinators that claimed this "
                                       "run while it ran (their session: what was done)")
    fidelity_raised: str | None = Field(None, description="why the judge raised the screen's fidelity")
    codesign: dict[str, Any] | None = Field(None, description="a co-designed run: what the calibration covers (the "
                                            "base body), the judge's ratios on sampled bodies, and `statement`")
    unservable_workers: dict[str, str] = Field(default_factory=dict, description="workers left out of this run "
                                               "(worker id: why it cannot serve it); the others go on with it")


class ErrorDetail(BaseModel):
    code: str
    message: str


class ErrorResponse(BaseModel):
    detail: ErrorDetail
