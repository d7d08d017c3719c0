"""The recording: a robot's motion over time, whatever made it (our own trial, NTRT, a motion-capture rig).

Units and frame: metres and seconds in spinefarm's world frame (Y up, the ground's top at y = 0.5 cm as in
robot.scene); orientations as unit quaternions (w, x, y, z), the identity in the robot's build pose. Any rate;
time strictly increasing. A recording checks itself on construction and against a robot (`check_robot`):
every refusal is one line naming what was found and what was expected.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from spinefarm.protocol.errors import SpinefarmError

FORMAT = "spinefarm-recording/1"
DRIVE_KINDS = ("controller", "rest_lengths")


class RecordingError(SpinefarmError, ValueError):
    """A recording is malformed or does not fit the robot it is read for."""

    code = "invalid_recording"


@dataclass
class Recording:
    """time_s (n,); position_m (n, n_segments, 3) segment COMs; quat_wxyz (n, n_segments, 4); optional
    string_length_m, rest_length_m (n, n_strings) m and tension_n (n, n_strings) N; drive: what moved the
    robot ({"kind": "controller", "controller": name, "params": {name: value}} or {"kind": "rest_lengths"},
    the strings then driven by rest_length_m); scene: the scene's dict (robot.scene); source: where it came from."""

    time_s: np.ndarray
    position_m: np.ndarray
    quat_wxyz: np.ndarray
    string_length_m: np.ndarray | None = None
    rest_length_m: np.ndarray | None = None
    tension_n: np.ndarray | None = None
    drive: dict[str, Any] = field(default_factory=lambda: {"kind": "rest_lengths"})
    scene: dict[str, Any] = field(default_factory=dict)
    source: str = ""
    morphology: str = ""

    def __post_init__(self) -> None:
        self.time_s = np.asarray(self.time_s, dtype=float)
        self.position_m = np.asarray(self.position_m, dtype=float)
        self.quat_wxyz = np.asarray(self.quat_wxyz, dtype=float)
        n = len(self.time_s)
        if self.time_s.ndim != 1 or n < 2:
            raise RecordingError(f"{self.where}time_s is not a series", received=f"shape {self.time_s.shape}",
                                 expected="at least 2 rows")
        for name, arr, cols in (("position_m", self.position_m, 3), ("quat_wxyz", self.quat_wxyz, 4)):
            if arr.ndim != 3 or arr.shape[0] != n or arr.shape[2] != cols:
                raise RecordingError(f"{self.where}{name} has the wrong shape", received=arr.shape,
                                     expected=f"({n}, n_segments, {cols})")
        if self.quat_wxyz.shape[1] != self.position_m.shape[1]:
            raise RecordingError(f"{self.where}quat_wxyz and position_m differ in segments",
                                 received=self.quat_wxyz.shape[1], expected=self.position_m.shape[1])
        for name in ("string_length_m", "rest_length_m", "tension_n"):
            self._check_strings(name)
        self._check_values()
        if self.drive.get("kind") not in DRIVE_KINDS:
            raise RecordingError(f"{self.where}unknown drive", received=self.drive.get("kind"),
                                 expected=f"one of {list(DRIVE_KINDS)}")
        if self.drive["kind"] == "rest_lengths" and self.rest_length_m is None:
            raise RecordingError(f"{self.where}a rest-length drive without rest lengths", received="no rest_length_m",
                                 expected="rest_length_m (n, n_strings)")

    @property
    def where(self) -> str:
        return f"{self.source}: " if self.source else ""

    @property
    def n_segments(self) -> int:
        return int(self.position_m.shape[1])

    @property
    def n_strings(self) -> int | None:
        for arr in (self.rest_length_m, self.string_length_m, self.tension_n):
            if arr is not None:
                return int(arr.shape[1])
        return None

    def _check_strings(self, name: str) -> None:
        arr = getattr(self, name)
        if arr is None:
            return
        arr = np.asarray(arr, dtype=float)
        setattr(self, name, arr)
        if arr.ndim != 2 or arr.shape[0] != len(self.time_s):
            raise RecordingError(f"{self.where}{name} has the wrong shape", received=arr.shape,
                                 expected=f"({len(self.time_s)}, n_strings)")

    def _check_values(self) -> None:
        for name in ("time_s", "position_m", "quat_wxyz", "string_length_m", "rest_length_m", "tension_n"):
            arr = getattr(self, name)
            if arr is not None and not np.all(np.isfinite(arr)):
                row = int(np.argwhere(~np.isfinite(arr))[0][0])
                bad = arr.reshape(len(arr), -1)[row]
                raise RecordingError(f"{self.where}{name} holds a non-finite value",
                                     received=f"{bad[~np.isfinite(bad)][0]} at row {row}", expected="finite numbers")
        steps = np.diff(self.time_s)
        if np.any(steps <= 0):
            row = int(np.argmax(steps <= 0)) + 1
            raise RecordingError(f"{self.where}time is not increasing",
                                 received=f"t = {self.time_s[row]:g} s at row {row} after {self.time_s[row - 1]:g} s",
                                 expected="strictly increasing time_s")
        norms = np.linalg.norm(self.quat_wxyz, axis=2)
        if np.any(np.abs(norms - 1.0) > 1e-3):
            row, seg = (int(i) for i in np.argwhere(np.abs(norms - 1.0) > 1e-3)[0])
            raise RecordingError(f"{self.where}an orientation is not a unit quaternion",
                                 received=f"norm {norms[row, seg]:.4g} at row {row}, segment {seg}",
                                 expected="norm 1 within 1e-3")

    def check_robot(self, n_segments: int, n_strings: int, robot: str,
                    driven: np.ndarray | None = None) -> np.ndarray:
        """The robot's strings the recording's string columns are, in order: all of them, or, when the recording
        lists only the controller-driven strings (NTRT records its muscles, not the passive ligaments or
        intercostals), `driven`. A recording of another robot (segment or string counts) is refused."""
        if self.n_segments != n_segments:
            raise RecordingError(f"{self.where}the recording does not fit {robot}",
                                 received=f"{self.n_segments} segments", expected=f"{n_segments} segments")
        if self.n_strings is None or self.n_strings == n_strings:
            return np.arange(n_strings)
        if driven is not None and self.n_strings == len(driven):
            return np.asarray(driven, dtype=int)
        also = "" if driven is None or len(driven) == n_strings else f" (or {len(driven)}, the driven ones)"
        raise RecordingError(f"{self.where}the recording does not fit {robot}",
                             received=f"{self.n_strings} strings", expected=f"{n_strings} strings{also}")

    def save(self, path: Path) -> None:
        """Write the spinefarm recording format (.npz; docs/recordings.md)."""
        arrays = {k: getattr(self, k) for k in ("time_s", "position_m", "quat_wxyz", "string_length_m",
                                                 "rest_length_m", "tension_n") if getattr(self, k) is not None}
        np.savez_compressed(path, format=FORMAT, drive_json=json.dumps(self.drive),
                            scene_json=json.dumps(self.scene), morphology=self.morphology, **arrays)
