"""The per-trial table every storage holds, its columns, units and the file schema version.

One row per trial, indexed by trial id (row i is trial i). A row is written when the trial is
sampled (status "waiting") and filled once when its result arrives (complete | failed).
"""

from __future__ import annotations

import math
import secrets
import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from spinefarm.protocol.columns import RECORDED_EXTRAS, SCORE_PARTS, Column, column_group
from spinefarm.protocol.settings import RunSettings
from spinefarm.protocol.states import STORED_STATUSES, AuditState, Verification

FILE_SCHEMA_VERSION = 9
# Older layouts that still open everywhere (read, served, resumed: a resumed copy is written at the current
# version), and what each lacks. 7: no /evaluations table; "not_reproduced" verdicts (a fixed 5 % tolerance).
# 8: evaluation rows without their cost of transport.
_LACKS = {7: "its judge, audit and referee runs are only the verdict columns of the rows they checked, not rows "
             "of their own",
          8: "its evaluation rows hold no cost of transport: the judge's COT is not measured"}
OLDER_SCHEMA_VERSIONS = tuple(_LACKS)


def older_file_note(version: int) -> str | None:
    """What an older run file lacks, in one line (None for the current version)."""
    if version == FILE_SCHEMA_VERSION:
        return None
    return f"an older run file (schema {version}, now {FILE_SCHEMA_VERSION}): {_LACKS.get(version, 'unknown')}"

# A sampler names its own phases: any short lower-case name is a valid phase (no list to extend here).
PHASE_PATTERN = rb"^[a-z][a-z0-9_]{0,15}$"
STATUSES = tuple(s.value for s in STORED_STATUSES)


# Vector columns (params_unit, params) are (n_trials, n_params); all others are (n_trials,). The columns,
# their units and descriptions are declared in protocol/columns.toml.
COLUMNS: tuple[Column, ...] = (*column_group("trial"), *SCORE_PARTS, *column_group("outcome"), *RECORDED_EXTRAS,
                               *column_group("summary"))
VERIFICATIONS = tuple(v.value for v in Verification)
AUDITS = tuple(a.value for a in AuditState)
COLUMN_BY_NAME = {c.name: c for c in COLUMNS}
VECTOR_COLUMNS = ("params_unit", "params")


def json_number(x: float) -> float | None:
    """A stored float as JSON holds it: NaN (not measured) and infinities become null."""
    return float(x) if math.isfinite(x) else None


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
    # every time a coordinator opened the run for writing, oldest first: {"instance", "how", "opened_at_unix_s"}
    instances: tuple[dict[str, Any], ...] = ()

    @property
    def instance(self) -> str:
        """The run instance of the coordinator that opened the file last ("" before any did)."""
        return str(self.instances[-1]["instance"]) if self.instances else ""

    def opened(self, how: str) -> RunMeta:
        """This run opened for writing once more ("create" or "resume"): a fresh instance id in its history
        (start time in ms, so an earlier instance sorts first, and 64 random bits a copy cannot share)."""
        now = time.time()
        entry = {"instance": f"{int(now * 1000)}-{secrets.token_hex(8)}", "how": how, "opened_at_unix_s": now}
        return replace(self, instances=(*self.instances, entry))

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
    body_hash: str = ""
    continued_s: float = float("nan")
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
