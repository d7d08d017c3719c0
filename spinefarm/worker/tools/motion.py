"""A trial's motion as one compact JSON document: what the dashboard's 3D view plays and `render --video` draws.

The geometry goes once, in body frames (rod end points, string anchors, cm); each frame carries only the
bodies' poses (COM cm + quaternion xyzw), the string tensions (N) and the robot's centre of mass (cm), so a
30 s gait of a 12-segment spine at 30 frames per second is a few hundred kB. Y is up; the flat ground's top
is at GROUND_TOP_CM.

`python -m spinefarm.worker.tools.motion JOB.json OUT.json` re-simulates a stored trial as its run did (the API
calls it in a subprocess, as it does for pictures). JOB holds morphology (a Morphology.to_dict() or a
name), controller, trial_config, params_unit, seed.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

FORMAT = "spinefarm-motion/1"
FRAMES_PER_S = 30.0
MAX_FRAMES = 1800
GROUND_TOP_CM = 0.5
DIGITS = 3  # positions to 0.01 mm, quaternions to 1e-3 (an angle error below 0.1 degree)


def record_every_s(duration_s: float) -> float:
    """The recording interval of a trial of `duration_s`: 30 frames a second, at most MAX_FRAMES frames."""
    return max(1.0 / FRAMES_PER_S, duration_s / MAX_FRAMES)


def _round(a: np.ndarray, digits: int = DIGITS) -> list[Any]:
    return np.round(np.asarray(a, dtype=float), digits).tolist()


def geometry(morph: Any) -> dict[str, Any]:
    """Rods (n_rods: body, end a (3,), end b (3,), radius) and strings (n_strings: body a, anchor a, body b,
    anchor b) in body frames (cm), and the bodies' masses (kg) for the centre of mass."""
    from spinefarm.robot.bodies import build_bodies, build_strings

    bodies = build_bodies(morph.structure)
    geom = build_strings(morph.structure, bodies)
    rods = []
    for body in bodies:
        for rod in body.rods:
            half = rod.rotation @ np.array([0.0, rod.length_cm / 2, 0.0])
            rods.append({"body": body.index, "a_cm": _round(rod.centre_cm - half), "b_cm": _round(rod.centre_cm + half),
                         "radius_cm": round(float(rod.radius_cm), DIGITS)})
    strings = [{"body_a": int(geom.body_a[i]), "anchor_a_cm": _round(geom.anchor_a_cm[i]),
                "body_b": int(geom.body_b[i]), "anchor_b_cm": _round(geom.anchor_b_cm[i])}
               for i in range(len(geom.body_a))]
    return {"n_bodies": len(bodies), "rods": rods, "strings": strings,
            "masses_kg": [float(b.mass_kg) for b in bodies]}


def motion_document(morph: Any, record: dict[str, np.ndarray], result: Any, title: str) -> dict[str, Any]:
    """The JSON-ready motion of one recorded trajectory (Trajectory.arrays() layout); result: its TrialResult
    (None for a trajectory read from a file)."""
    from spinefarm.protocol.errors import ConfigError

    geo = geometry(morph)
    t = np.asarray(record.get("time_s", []), dtype=float)
    poses = np.asarray(record.get("poses", np.zeros((0, geo["n_bodies"], 7))), dtype=float)
    tension = np.asarray(record.get("tension_n", np.zeros((0, len(geo["strings"])))), dtype=float)
    if len(t) == 0:
        raise ConfigError("nothing was recorded", received=0, expected="at least one recorded frame")
    if poses.shape[1:] != (geo["n_bodies"], 7) or tension.shape[1:] != (len(geo["strings"]),):
        raise ConfigError("the record does not fit this morphology",
                          received=f"poses {poses.shape}, tension {tension.shape}",
                          expected=f"poses (n, {geo['n_bodies']}, 7) and tension (n, {len(geo['strings'])})")
    masses = np.asarray(geo["masses_kg"])
    com = (poses[:, :, :3] * masses[None, :, None]).sum(axis=1) / masses.sum()
    finite = lambda x: float(x) if math.isfinite(float(x)) else None  # noqa: E731
    return {
        "format": FORMAT, "title": title, "morphology": morph.name,
        "units": {"length": "cm", "time": "s", "tension": "N", "quaternion": "xyzw"},
        "up": "y", "ground_top_cm": GROUND_TOP_CM, **geo,
        "time_s": _round(t, 4), "poses": _round(poses.reshape(len(t), -1)), "tension_n": _round(tension, 2),
        "com_cm": _round(com), "tension_max_n": round(float(np.max(tension)) if tension.size else 0.0, 2),
        "result": None if result is None else {
            "distance_m": finite(result.distance_m), "speed_cm_s": finite(result.speed_cm_s),
            "cot": finite(result.cot), "status": str(getattr(result.status, "value", result.status)),
            "reason": result.reason or None},
    }


def motion_record(motion: dict[str, Any]) -> dict[str, np.ndarray]:
    """A motion document back as Trajectory.arrays() arrays (time_s, poses (n, n_bodies, 7), tension_n)."""
    t = np.asarray(motion["time_s"], dtype=float)
    return {"time_s": t, "poses": np.asarray(motion["poses"], dtype=float).reshape(len(t), motion["n_bodies"], 7),
            "tension_n": np.asarray(motion["tension_n"], dtype=float)}


def simulate_motion(job: dict[str, Any]) -> dict[str, Any]:
    """Re-simulate a stored trial with recording on and return its motion document."""
    from spinefarm.robot.codesign import job_robot
    from spinefarm.worker.trial.simulation import TrialConfig, simulate

    morph, unit = job_robot(job)  # a co-designed trial's own body
    base = dict(job["trial_config"])
    duration = float(base.get("duration_s") or morph.duration_s) + float(base.get("settle_s") or 0.0)
    base["record_every_s"] = record_every_s(duration)
    outcome = simulate(morph, unit, TrialConfig.from_dict(base),
                       int(job["seed"]), controller=job.get("controller"))
    record = outcome.trajectory.arrays() if outcome.trajectory is not None else {}
    return motion_document(morph, record, outcome.result, str(job.get("title", morph.name)))


def main(argv: list[str]) -> int:
    from spinefarm.protocol.errors import SpinefarmError

    if len(argv) != 2:
        print("usage: python -m spinefarm.worker.tools.motion JOB.json OUT.json", file=sys.stderr)
        return 2
    try:
        doc = simulate_motion(json.loads(Path(argv[0]).read_text()))
    except SpinefarmError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    Path(argv[1]).write_text(json.dumps(doc, separators=(",", ":"), allow_nan=False))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
