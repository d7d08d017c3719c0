"""What one run of a world measured, declared once: a trial's result (protocol.results.TrialResult) and each
robust episode's (protocol.robust.EpisodeResult) carry these fields, in this order, on the wire and in their
constructors."""

from __future__ import annotations

from dataclasses import dataclass, fields


@dataclass(frozen=True)
class Measured:
    """status: complete or failed, with `reason` (diverged: ..., error: ...); then the parts of the score,
    units in the names (protocol.results.SCORE_PARTS describes each). A dataclass deriving from it lists its
    own fields after these, and the fields of a base named after this one before them."""

    status: str
    reason: str
    distance_m: float
    ntrt_distance_cm: float
    speed_cm_s: float
    work_j: float
    cot: float
    sim_time_s: float
    wall_time_s: float


MEASURED_NUMBERS = tuple(f.name for f in fields(Measured) if f.name not in ("status", "reason"))
