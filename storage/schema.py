"""The per-trial table every storage holds, its columns, units and the file schema version.

One row per trial, indexed by trial id (row i is trial i). A row is written when the trial is
sampled (status "waiting") and filled once when its result arrives (complete | failed).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from spinefarm.protocol.results import RECORDED_EXTRAS, SCORE_NAMES, SCORE_PARTS, Column
from spinefarm.protocol.settings import RunSettings
from spinefarm.protocol.states import STORED_STATUSES, AuditState, Verification

FILE_SCHEMA_VERSION = 7

# A sampler names its own phases: any short lower-case name is a valid phase (no list to extend here).
PHASE_PATTERN = rb"^[a-z][a-z0-9_]{0,15}$"
STATUSES = tuple(s.value for s in STORED_STATUSES)


# Vector columns (params_unit, params) are (n_trials, n_params); all others are (n_trials,).
COLUMNS: tuple[Column, ...] = (
    Column("trial_id", "i8", "", "trial number; equals the row index"),
    Column("params_unit", "f8", "1", "parameter vector in the unit cube; columns named by param_names"),
    Column("params", "f8", "see param_units", "physical parameter values, low + u * (high - low)"),
    Column("phase", "S16", "", "sampler phase (the sampler's own name for it: monte_carlo, gaussian, cmaes, "
           "tpe, ...), or promoted (a multi-fidelity re-run of its parent at a longer rung)"),
    Column("parent", "i8", "", "trial id of the centre a gaussian sample was drawn around; -1 for none"),
    Column("seed", "i8", "", "simulation seed of the trial"),
    Column("rung", "i8", "", "fidelity rung of a multi-fidelity search (0: the screen); a promoted row re-runs its "
           "parent's parameters at the next rung"),
    Column("duration_s", "f8", "s", "simulated duration the trial was asked for (NaN: the run's)"),
    Column("status", "S16", "", "waiting (sampled, no result yet), complete or failed"),
    Column("reason", "S160", "", "why a trial failed (diverged: ..., error: ...); empty when complete"),
    Column("objective", "f8", "see attribute objective", "the score the search maximised"),
    *SCORE_PARTS,
    Column("worker_id", "S64", "", "worker that ran the trial"),
    Column("finished_at_unix_s", "f8", "s since 1970-01-01 UTC", "when the coordinator stored the result"),
    Column("verification", "S16", "", "the judge's re-simulation of a trial that became best: empty (not "
           "checked), pending, holds (same engine, within tolerance), judged (in another engine: its distance "
           "counts) or not_reproduced (then it never counts as best)"),
    Column("verify_distance_m", "f8", "m", "distance of that re-simulation (the judge's distance)"),
    Column("verify_reason", "S160", "", "what the re-simulation found when the distance did not hold"),
    Column("judge_ratio", "f8", "1", "screen-to-judge distance ratio, distance_m / verify_distance_m"),
    Column("audit", "S16", "", "re-simulation on another worker at the same fidelity: empty (not audited), "
           "pending, agrees or disagrees (then the result never counts as best)"),
    Column("audit_distance_m", "f8", "m", "distance the auditing worker measured"),
    Column("audit_worker_id", "S64", "", "worker that audited the result"),
    *RECORDED_EXTRAS,
    Column("pareto_front", "i1", "", "1 if the trial is on the Pareto front of speed (max) and COT (min) among "
           "complete trials, else 0; kept up to date as results arrive"),
)
VERIFICATIONS = tuple(v.value for v in Verification)
AUDITS = tuple(a.value for a in AuditState)
COLUMN_BY_NAME = {c.name: c for c in COLUMNS}
VECTOR_COLUMNS = ("params_unit", "params")
SCORE_COLUMNS = SCORE_NAMES
EXTRA_COLUMNS = tuple(e.name for e in RECORDED_EXTRAS)


def planned_evaluations(trials_budget: int, settings: RunSettings) -> int:
    """Evaluations a run expects: its budget of parameter sets, plus with successive halving about
    budget / eta^r promotions to each rung r."""
    return settings.planned_evaluations(trials_budget)


@dataclass(frozen=True)
class RunMeta:
    """Run-level metadata, stored as file attributes. JSON-able dicts stay dicts here."""

    run_id: str
    morphology: str
    controller: str | None
    param_names: tuple[str, ...]
    param_lows: tuple[float, ...]
    param_highs: tuple[float, ...]
    param_units: tuple[str, ...]
    objective: str
    seed: int
    trials_budget: int
    sampler: dict[str, Any]
    software_version: str
    created_at_unix_s: float
    config_hash: str = ""
    settings: RunSettings = field(default_factory=RunSettings)   # how the run searches, typed
    run: dict[str, Any] = field(default_factory=dict)   # the RunConfig, stored once
    environment: dict[str, Any] = field(default_factory=dict)   # what created the run (protocol.environment)

    @property
    def n_params(self) -> int:
        return len(self.param_names)

    @property
    def morphology_spec(self) -> dict[str, Any]:
        return self.run.get("morphology_spec", {})

    @property
    def trial_config(self) -> dict[str, Any]:
        return self.run.get("trial_config", {})


@dataclass(frozen=True)
class TrialRecord:
    """One row of the table, decoded."""

    trial_id: int
    params_unit: tuple[float, ...]
    params: tuple[float, ...]
    phase: str
    parent: int
    seed: int
    status: str
    reason: str
    objective: float
    distance_m: float
    ntrt_distance_cm: float
    speed_cm_s: float
    work_j: float
    cot: float
    mass_kg: float
    sim_time_s: float
    wall_time_s: float
    worker_id: str
    finished_at_unix_s: float
    verification: str = ""
    verify_distance_m: float = float("nan")
    verify_reason: str = ""
    judge_ratio: float = float("nan")
    audit: str = ""
    audit_distance_m: float = float("nan")
    audit_worker_id: str = ""
    engine: str = ""
    dt_s: float = float("nan")
    rung: int = 0
    duration_s: float = float("nan")
    settle_s: float = float("nan")
    time_limit_s: float = float("nan")
    pareto_front: int = 0

    @classmethod
    def from_columns(cls, cols: dict[str, np.ndarray], i: int) -> TrialRecord:
        kw: dict[str, Any] = {}
        for c in COLUMNS:
            v = cols[c.name][i]
            if c.name in VECTOR_COLUMNS:
                kw[c.name] = tuple(float(x) for x in v)
            elif c.dtype.startswith("S"):
                kw[c.name] = v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v)
            elif c.dtype.startswith("i"):
                kw[c.name] = int(v)
            else:
                kw[c.name] = float(v)
        return cls(**kw)

    def to_dict(self) -> dict[str, Any]:
        return {c.name: getattr(self, c.name) for c in COLUMNS}

    def __eq__(self, other: object) -> bool:
        # rows are data: a missing value (NaN) equals a missing value
        if not isinstance(other, TrialRecord):
            return NotImplemented
        return all(a == b or (isinstance(a, float) and isinstance(b, float) and a != a and b != b)
                   for a, b in zip(self.to_dict().values(), other.to_dict().values(), strict=True))

    __hash__ = None  # type: ignore[assignment]
