"""A run's settings are typed and stored with it; a sampler's own phase needs no storage edit; the judge
watches the screen and raises the fidelity when its ratios drift (decided from storage, so resumed too)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from spinefarm.coordinator.problem import build_run_config
from spinefarm.coordinator.samplers import SAMPLERS
from spinefarm.coordinator.samplers.base import BaseSampler, Proposal, trial_rng
from spinefarm.coordinator.setup import SearchSettings, new_run, resume_run
from spinefarm.protocol.envelope import decode_message
from spinefarm.protocol.envelope import encode_message as enc
from spinefarm.protocol.errors import ConfigError
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.settings import JudgePolicy, Rung, RunSettings
from spinefarm.protocol.states import TrialStatus
from spinefarm.protocol.submissions import ResultSubmission, SubmittedResult
from spinefarm.protocol.work import WorkGrant, WorkRequest
from spinefarm.storage.hdf5_reader import read_meta
from tests.coordinator_tests.helpers import FakeClock


def test_run_settings_round_trip_typed_and_refuse_unknown_fields():
    s = RunSettings(scheduler="halving", ladder=(Rung("mujoco", 0.002, 3.0), Rung(duration_s=10.0)), eta=2,
                    judge=JudgePolicy(rung=Rung("bullet", 2.5e-4)))
    assert RunSettings.from_dict(s.to_dict()) == s
    with pytest.raises(ConfigError, match="unknown fields") as e:
        RunSettings.from_dict({**s.to_dict(), "verify": {}})
    assert "verify" in str(e.value) and "\n" not in str(e.value)
    with pytest.raises(ConfigError, match="increasing"):
        RunSettings(scheduler="halving", ladder=(Rung(duration_s=10.0), Rung(duration_s=3.0)))
    assert s.planned_evaluations(18) == 18 + 9


def test_the_stored_run_holds_its_settings_typed(tmp_path):
    config = build_run_config("typed", "sphere:3", duration_s=0.0)
    _, storage = new_run(config, SearchSettings(trials=9, rungs=(1.0, 2.0), eta=3, lease_s=7.0), tmp_path / "r.h5")
    storage.close()
    settings = read_meta(tmp_path / "r.h5").settings
    assert isinstance(settings, RunSettings) and settings.scheduler == "halving" and settings.lease_s == 7.0
    assert settings.durations_s() == (1.0, 2.0) and not settings.judge.enabled  # a test objective: no judge


class _StripesSampler(BaseSampler):
    """A sampler with a phase of its own, unknown to storage."""

    name = "stripes"

    def propose(self, trial_id: int, storage) -> Proposal:
        return Proposal(trial_rng(self.seed, trial_id).random(self.n_params), "stripes_phase", -1)


def _answer(core, worker: str, n: int, distance=lambda a: 1.0, wall_s=lambda a: 0.0) -> WorkGrant:
    """Take up to n tasks as `worker` and return each with `distance(assignment)` metres, having taken
    `wall_s(assignment)` seconds."""
    grant = decode_message(core.handle_work(enc(WorkRequest(worker, n))), WorkGrant)
    items = tuple(SubmittedResult(a.lease_id, TrialResult(TrialStatus.COMPLETE, "", distance(a), 0.0, 1.0, 1.0, 1.0,
                                                          1.0, wall_s(a), 1.0, a.seed, trial_id=a.trial_id))
                  for a in grant.assignments)
    if items:
        core.handle_results(enc(ResultSubmission(worker, items)))
    return grant


def test_a_sampler_with_its_own_phase_needs_no_storage_edit_and_resumes(tmp_path):
    SAMPLERS["stripes"] = _StripesSampler
    try:
        config = build_run_config("stripes", "sphere:3")
        core, storage = new_run(config, SearchSettings(trials=6, sampler="stripes"), tmp_path / "r.h5", FakeClock())
        _answer(core, "w1", 3)
        storage.close()
        core, storage = resume_run(tmp_path / "r.h5", FakeClock())  # every row validated, the phase too
        assert set(storage.columns()["phase"].tolist()) == {b"stripes_phase"}
        storage.close()
    finally:
        del SAMPLERS["stripes"]


def _screened_run(tmp_path, run_id: str):
    """A new 20-trial run screened in MuJoCo, its bests judged in Bullet at 0.25 ms, drift 0.2."""
    config = build_run_config(run_id, "sphere:3", trial_overrides={"engine": "mujoco"})
    judge = JudgePolicy(rung=Rung("bullet", 2.5e-4), drift=0.2)
    return new_run(config, SearchSettings(trials=20, judge=judge), tmp_path / "r.h5", FakeClock())


def test_drifting_judged_ratios_raise_the_screens_fidelity_and_a_resumed_run_keeps_it(tmp_path):
    """A MuJoCo screen judged in Bullet whose judge keeps measuring half the screen's distance: after three
    judged bests the screen is no longer trusted and new trials run in Bullet at 4x the judge's step."""
    core, storage = _screened_run(tmp_path, "drift")
    judged = 0
    try:
        for _ in range(40):
            grant = _answer(core, "w1", 1, lambda a: 0.5 * (a.trial_id + 1) if a.fidelity.task == "judge"
                            else float(a.trial_id + 1))  # every trial a new best; the judge measures half
            judged += sum(a.fidelity.task == "judge" for a in grant.assignments)
            if core.drift:
                break
        assert judged == 3 and "ratio 2" in core.drift and core.status()["fidelity_raised"] == core.drift
        cols = storage.columns()
        ratios = cols["judge_ratio"][np.isfinite(cols["judge_ratio"])]
        assert ratios.tolist() == [2.0, 2.0, 2.0] and set(cols["verification"][cols["verification"] != b""]
                                                          .tolist()) <= {b"judged", b"pending"}
        grant = decode_message(core.handle_work(enc(WorkRequest("w1", 1))), WorkGrant)
        f = grant.assignments[0].fidelity
        if f.task == "trial":
            assert (f.engine, f.dt_s) == ("bullet", pytest.approx(1e-3))
    finally:
        storage.close()
    core, storage = resume_run(tmp_path / "r.h5", FakeClock())
    try:
        assert core.drift is not None  # decided from the stored ratios
        f = core.ladder.checks.trial_fidelity(0, core.drift is not None)
        assert (f.engine, f.dt_s) == ("bullet", pytest.approx(1e-3)) and not math.isnan(f.dt_s)
    finally:
        storage.close()


def test_bests_that_barely_move_do_not_raise_the_fidelity(tmp_path):
    """The first bests of a search move a few cm, where a step's error of millimetres is a factor: their judged
    ratios (here 4) must not halve the step for the whole run."""
    core, storage = _screened_run(tmp_path, "still")
    judged = 0
    try:
        for _ in range(40):
            grant = _answer(core, "w1", 1, lambda a: 0.00025 * (a.trial_id + 1) if a.fidelity.task == "judge"
                            else 0.001 * (a.trial_id + 1))  # every trial a new best, 1-20 mm; the judge a quarter
            judged += sum(a.fidelity.task == "judge" for a in grant.assignments)
            if judged >= 6:
                break
        ratios = storage.columns()["judge_ratio"]
        assert judged >= 6 and np.allclose(ratios[np.isfinite(ratios)], 4.0)
        assert core.drift is None and core.status()["fidelity_raised"] is None
    finally:
        storage.close()


def test_judge_drift_from_the_command_line_is_stored_and_a_wider_band_keeps_the_screen(tmp_path):
    """`--judge-drift 1.5`: a screen that measures twice the judge's distance (a scale, not a misranking) keeps
    its fidelity; the band is in the stored run, so a resumed run keeps it too."""
    from spinefarm.cli.main import build_parser
    from spinefarm.cli.run_setup import run_config

    args = build_parser().parse_args(["search", "sphere:3", "--engine", "mujoco", "--verify-engine", "bullet",
                                      "--verify-dt", "0.00025", "--judge-drift", "1.5", "--trials", "20"])
    config, settings = run_config(args, "wide")
    assert settings.judge.drift == 1.5 and settings.judge.rung.engine == "bullet"
    core, storage = new_run(config, settings, tmp_path / "r.h5", FakeClock())
    judged = 0
    try:
        for _ in range(40):
            grant = _answer(core, "w1", 1, lambda a: 0.5 * (a.trial_id + 1) if a.fidelity.task == "judge"
                            else float(a.trial_id + 1))  # the judge measures half, as in the drift test above
            judged += sum(a.fidelity.task == "judge" for a in grant.assignments)
            if judged >= 6:
                break
        ratios = storage.columns()["judge_ratio"]
        assert judged >= 6 and np.allclose(ratios[np.isfinite(ratios)], 2.0) and core.drift is None
    finally:
        storage.close()
    assert read_meta(tmp_path / "r.h5").settings.judge.drift == 1.5
    core, storage = resume_run(tmp_path / "r.h5", FakeClock())
    try:
        assert core.ladder.checks.settings.judge.drift == 1.5 and core.drift is None
    finally:
        storage.close()


def _judged_while_searching(tmp_path, share: float) -> tuple[list[tuple[float, float]], str]:
    """A 60-trial MuJoCo screen where every trial is a new best and takes 1 s, and the judge's Bullet run 10 s:
    (trial seconds and judge seconds spent when each judge was leased, the final best's verification)."""
    config = build_run_config(f"share{share}", "sphere:3", trial_overrides={"engine": "mujoco"})
    judge = JudgePolicy(rung=Rung("bullet", 2.5e-4), drift=10.0, share=share)
    core, storage = new_run(config, SearchSettings(trials=60, judge=judge), tmp_path / f"{share}.h5", FakeClock())
    spent = {"trial": 0.0, "judge": 0.0}
    leased: list[tuple[float, float]] = []

    def cost_s(a) -> float:
        return 10.0 if a.fidelity.task == "judge" else 1.0

    try:
        for _ in range(200):
            grant = _answer(core, "w1", 1, lambda a: float(a.trial_id + 1), cost_s)
            for a in grant.assignments:
                if a.fidelity.task == "judge":
                    leased.append((spent["trial"], spent["judge"]))
                spent[a.fidelity.task] += cost_s(a)
            if core.done:
                break
        assert core.done
        best = storage.best_ids(1)[0]
        return leased, storage.columns()["verification"][best].decode()
    finally:
        storage.close()


def test_the_judge_takes_at_most_its_share_of_the_workers_time_and_always_judges_the_final_best(tmp_path):
    """Early bests are overtaken within seconds and each judge costs many trials: with --judge-share 0.25 a
    judge is leased only while the judge's time so far is at most a quarter of all time spent; the best at the
    end is judged even past the share. Share 1 judges every new best at once."""
    paced, verdict = _judged_while_searching(tmp_path, 0.25)
    assert verdict == "judged"
    during = paced[:-1]  # the last one: the final best, judged after the search whatever it cost
    assert len(during) >= 2 and all(judge_s <= 0.25 * (trial_s + judge_s) for trial_s, judge_s in during)
    assert paced[-1][0] == 60.0
    every, verdict = _judged_while_searching(tmp_path, 1.0)
    assert verdict == "judged" and len(every) >= 50 and len(paced) <= 4


def test_judge_share_from_the_command_line_is_stored(tmp_path):
    from spinefarm.cli.main import build_parser
    from spinefarm.cli.run_setup import run_config

    args = build_parser().parse_args(["search", "sphere:3", "--engine", "mujoco", "--verify-engine", "bullet",
                                      "--judge-share", "0.5", "--trials", "4"])
    config, settings = run_config(args, "share")
    assert settings.judge.share == 0.5
    _, storage = new_run(config, settings, tmp_path / "r.h5", FakeClock())
    storage.close()
    assert read_meta(tmp_path / "r.h5").settings.judge.share == 0.5
    assert JudgePolicy.from_dict({"drift": 0.3}).share == 0.25  # a run stored before the share: the default
    with pytest.raises(ConfigError, match="judge share"):
        JudgePolicy(share=0.0)


def _r(distance: float, ok: bool = True) -> TrialResult:
    status = TrialStatus.COMPLETE if ok else TrialStatus.FAILED
    return TrialResult(status, "" if ok else "diverged: x", distance, 0.0, 1.0, 1.0, 1.0, 1.0, 0.0, 1.0, 0)


def test_a_verdict_says_holds_only_within_tolerance_at_the_same_engine():
    from spinefarm.protocol.verdicts import judge_verdict

    assert judge_verdict(1.0, False, "bullet", _r(1.04), 0.05)[0] == "holds"
    verdict, reason = judge_verdict(1.0, False, "bullet", _r(0.5), 0.05)
    assert verdict == "moved" and reason.startswith("moved 50.0% at the finer step (1 m -> 0.5 m")
    assert judge_verdict(0.0229, True, "bullet", _r(0.0411), 0.05)[0] == "judged"  # never "holds" across engines
    assert judge_verdict(1.0, True, "bullet", _r(1.0, ok=False), 0.05)[0] == "diverged"


def test_a_cross_engine_judgement_is_reported_as_judged_in_bullet_with_both_distances_and_their_ratio():
    from spinefarm.cli.report import verdict_text
    from spinefarm.storage.schema import TrialRecord

    fields = dict.fromkeys(("objective", "distance_m", "ntrt_distance_cm", "speed_cm_s", "work_j", "cot",
                            "mass_kg", "sim_time_s", "wall_time_s", "finished_at_unix_s"), 1.0)
    rec = TrialRecord(0, (0.5,), (0.5,), "cmaes", -1, 0, "complete", "", worker_id="w", **{
        **fields, "distance_m": 0.0229, "sim_time_s": 10.0}, verification="judged", verify_distance_m=0.0411,
        judge_ratio=0.0229 / 0.0411)
    text = verdict_text(rec, "bullet")
    assert text.startswith("judged in bullet: 0.0411 m") and "screen 0.0229 m" in text and "ratio 0.557" in text
    assert "holds" not in text
