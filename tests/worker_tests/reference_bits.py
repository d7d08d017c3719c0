"""Reference distances, to the bit, of NTRT's replays, the shipped gaits and a MuJoCo screen (2 s each).

`python -m tests.worker_tests.reference_bits` (from the repository) runs every case through the
`spinefarm` command in a fresh process and writes tests/worker_tests/data/reference_bits.json; the test
(test_reference_bits.py) runs the same commands in-process and compares `repr(float)` of the distances.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DATA = Path(__file__).parent / "data" / "reference_bits.json"
REPLAYS = ("tetraspine-ntrt", "tetrahedral-complex", "octahedral-complex", "ribbed")
GAITS = ("tetraspine", "tetrahedral-complex", "octahedral-complex", "ribbed")
SCREEN = ["--dt", "0.002", "--engine-option", "segment_contacts=off"]


def cases() -> dict[str, list[str]]:
    """name -> the `spinefarm` arguments of each case (each ends with --json)."""
    out: dict[str, list[str]] = {}
    for engine in ("bullet", "mujoco"):
        for robot in REPLAYS:
            out[f"replay/{robot}/{engine}"] = ["replay", robot, "--duration", "2", "--engine", engine, "--json"]
        for robot in GAITS:
            gait = str(ROOT / "examples" / "gaits" / f"{robot}.json")
            out[f"gait/{robot}/{engine}"] = ["trial", robot, "--params", gait, "--duration", "2",
                                             "--engine", engine, "--json"]
    out["screen/tetraspine/mujoco"] = ["trial", "tetraspine", "--params",
                                       str(ROOT / "examples" / "gaits" / "tetraspine.json"), "--duration", "2",
                                       "--engine", "mujoco", *SCREEN, "--json"]
    return out


def distances(printed: dict) -> dict[str, str]:
    """The distances a case printed, as repr(float) (replays: NTRT's and the robot's; trials: the COM's)."""
    keys = ("ntrt_distance_cm", "robot_distance_cm") if "robot_distance_cm" in printed else \
        ("distance_m", "ntrt_distance_cm")
    return {k: repr(float(printed[k])) for k in keys} | {"status": printed["status"]}


def record() -> dict[str, dict[str, str]]:
    out = {}
    for name, argv in cases().items():
        done = subprocess.run([sys.executable, "-m", "spinefarm", *argv], capture_output=True, text=True, check=True)
        out[name] = distances(json.loads(done.stdout.strip().splitlines()[-1]))
        print(name, out[name], flush=True)
    return out


if __name__ == "__main__":
    DATA.write_text(json.dumps(record(), indent=1) + "\n")
