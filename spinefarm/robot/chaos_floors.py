"""A robot's chaos floor: the relative change of a distance that chaos alone makes, and so the tolerance
a re-simulation's "holds" is held to (the search's judge and `verify_trial` read it here).

A built-in robot uses its measured floor (chaos_floors.json beside this module, its source and command
inside), never below 1 %, the accuracy docs' criterion; any other robot the file's documented default.
"""

from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path
from typing import Any

from spinefarm.robot.morphology.registry import builtin_names, load_morphology

CHAOS_FLOORS_PATH = Path(__file__).resolve().parent / "chaos_floors.json"
MIN_HOLDS_TOLERANCE = 0.01  # below 1 % the step error itself shows (docs/accuracy.md: max(1 %, chaos floor))


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
