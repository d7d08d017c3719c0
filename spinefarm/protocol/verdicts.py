"""The judge's verdict on a distance it re-simulated, in the words every reader shows.

Same engine: "holds" when the finer step (and the perturbed run) changed the distance by at most the
robot's chaos floor (robot/chaos_floors.py answers it): a chaotic gait's change up to its floor is no
evidence of an artefact. Beyond it the verdict is "moved X % at the finer step": the set is kept and ranks
by its judged distance, the figure that counts either way. Another engine: "judged" (its distance counts).
A judge run that fails or gives no finite distance: "diverged", never best (the ladder first issues a run
stopped by its wall-clock limit again, coordinator/ladder/checks.py). The search's judge and
`spinefarm.worker.tools.verify` both decide here.
"""

from __future__ import annotations

import math

from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.states import Verification


def relative_change(a: float, b: float) -> float:
    return abs(a - b) / max(abs(b), 1e-9)


def judge_verdict(distance_m: float, cross_engine: bool, engine: str, r: TrialResult,
                  tolerance: float) -> tuple[Verification, str]:
    """The judge's verdict on a stored distance from its re-simulation `r` (and its perturbed run)."""
    if not r.ok or not math.isfinite(r.distance_m):
        why = f"{r.status}: {r.reason}" if not r.ok else f"distance {r.distance_m}"
        return Verification.DIVERGED, f"{engine or 'judge'} run {why}"
    if cross_engine:
        return Verification.JUDGED, ""
    runs = [("at the finer step", r.distance_m)]
    if "perturbed_distance_m" in r.extras:
        runs.append(("in the perturbed run", float(r.extras["perturbed_distance_m"])))
    moved = []
    for name, d in runs:
        change = relative_change(d, distance_m) if math.isfinite(d) else math.inf
        if change > tolerance:
            moved.append(f"moved {change:.1%} {name} ({distance_m:.4g} m -> {d:.4g} m; floor {tolerance:.1%})")
    return (Verification.MOVED, "; ".join(moved)) if moved else (Verification.HOLDS, "")
