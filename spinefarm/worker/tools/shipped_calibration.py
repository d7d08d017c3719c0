"""The built-ins' calibrations, shipped as package data (spinefarm/robot/calibrations/NAME.json, re-created by
`python bench/ship_calibrations.py`): a first `spinefarm calibrate NAME` or `search --engine auto` uses one at
once when it was made for this very model and these settings (the spec's hash and the settings' key, which
holds the profile's hash and the reference's step), and ignores it otherwise, so a changed constant or a
user's spec that only shares a built-in's name calibrates afresh."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Protocol

from spinefarm.robot.morphology.registry import load_morphology


class Keyed(Protocol):
    """A calibration's settings (worker.tools.calibrate.CalibrationSettings), by what its result depends on."""

    def key(self) -> str: ...

SHIPPED_DIR = Path(__file__).resolve().parents[2] / "robot" / "calibrations"


def shipped_path(name: str) -> Path:
    return SHIPPED_DIR / f"{name}.json"


def shipped(source: str, settings: Keyed) -> dict[str, Any] | None:
    """The shipped calibration of this robot under these settings, or None when there is none or it was made
    for another model (spec hash), other settings or another profile (the settings' key)."""
    morph = load_morphology(source)
    path = shipped_path(morph.name)
    if not path.is_file():
        return None
    try:
        result = json.loads(path.read_text())
    except (OSError, ValueError):
        return None  # a damaged file is as good as none: the calibration runs
    if result.get("spec_hash") != morph.spec_hash() or result.get("key") != settings.key():
        return None
    return result
