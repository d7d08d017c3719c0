"""The judge's verdict on a set it re-simulated, and the tolerance "holds" is held to.

Same engine: "holds" when the finer step (and the perturbed run) changed the distance by at most the
robot's chaos floor (at least 1 %, the accuracy docs' criterion): a chaotic gait's change up to its floor
is no evidence of an artefact. Beyond it the verdict is "moved X % at the finer step": the set is kept and
ranks by its judged distance, the figure that counts either way. Another engine: "judged" (its distance
counts). A judge run that fails or gives no finite distance: "diverged", never best.
"""

from __future__ import annotations

import json
import math
from functools import lru_cache
from pathlib import Path
from typing import Any

from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.states import Verification
from spinefarm.robot.morphology.registry import builtin_names, load_morphology

# measured floors beside the robots' specs (source and command inside the file)
CHAOS_FLOORS_PATH = Path(__file__).resolve().parents[1] / "robot" / "chaos_floors.json"
MIN_HOLDS_TOLERANCE = 0.01  # below 1 % the step error itself shows (docs/accuracy.md: max(1 %, chaos floor))


def relative_change(a: float, b: float) -> float:
    return abs(a - b) / max(abs(b), 1e-9)


@lru_cache(maxsize=1)
def chaos_floors() -> dict[str, Any]:
    return json.loads(CHAOS_FLOORS_PATH.read_text())


def holds_tolerance(morphology: str, morphology_spec: dict[str, Any], given: float | None) -> tuple[float, str]:
    """(relative tolerance for "holds", where it comes from). `given` (--verify-tolerance) wins; a built-in
    robot with a measured floor uses it when the run's body is that built-in's; any other robot the default."""
    if given is not None:
        return given, "given"
    table = chaos_floors()
    floor = table["floors"].get(morphology)
    if floor is not None and _is_builtin(morphology, morphology_spec):
        return max(MIN_HOLDS_TOLERANCE, floor), f"chaos floor of {morphology} {floor:.2%}"
    return max(MIN_HOLDS_TOLERANCE, table["default"]), f"default chaos floor {table['default']:.0%}"


def _is_builtin(name: str, spec: dict[str, Any]) -> bool:
    """The run's body is the built-in of that name (a user's edited copy keeps the name, not the floor)."""
    return name in builtin_names() and (not spec or load_morphology(name).to_dict() == spec)


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
