"""Re-create the built-ins' shipped calibrations (spinefarm/robot/calibrations/NAME.json, package data).

Each robot is calibrated as a user's `spinefarm calibrate NAME` would be, with the default settings (and the
automatic step for a robot whose default step is unstable), against the judge (Bullet at 0.25 ms), in a fresh
cache so that nothing stored is reused; its result is written where `calibrate` and `search --engine auto`
look first. Prints one JSON object: per robot its figures and decision, or why it failed.

    python bench/ship_calibrations.py                                 # every built-in (hours on 2 cores)
    python bench/ship_calibrations.py tetrahedral-complex tetraspine  # these
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

from spinefarm.robot.morphology.registry import builtin_names
from spinefarm.worker.tools.calibrate import simulating_code_digest
from spinefarm.worker.tools.shipped_calibration import shipped_path

FIGURES = ("spearman", "top_overlap", "top_k", "median_distance_ratio", "n_moving", "decision", "reason")


def ship(name: str, jobs: int) -> dict:
    """Calibrate one built-in with the defaults in a fresh cache and write its shipped file."""
    t0 = time.time()
    with tempfile.TemporaryDirectory(prefix="spinefarm-ship-") as cache:
        proc = subprocess.run([sys.executable, "-m", "spinefarm", "calibrate", name, "--json", "--refresh",
                               "--jobs", str(jobs)], stdout=subprocess.PIPE, text=True,
                              env={**os.environ, "SPINEFARM_CACHE_DIR": cache})
    if proc.returncode != 0:
        return {"error": f"spinefarm calibrate {name} exited with {proc.returncode}"}
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    for transient in ("cached", "shipped"):
        result.pop(transient, None)
    result["code"] = simulating_code_digest()  # what it was made with, for the record (not part of its key)
    path = shipped_path(name)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(result, indent=1) + "\n")
    return {**{k: result[k] for k in FIGURES}, "reference": result["reference"],
            "tiers": result["tiers"], "file": str(path), "wall_s": round(time.time() - t0, 1)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("robots", nargs="*", help="built-in names (default: every built-in)")
    ap.add_argument("--jobs", type=int, default=2, help="processes per calibration (default 2)")
    args = ap.parse_args()
    names = args.robots or builtin_names()
    unknown = sorted(set(names) - set(builtin_names()))
    if unknown:
        sys.exit(f"error: not a built-in: {unknown[0]!r} (expected one of {', '.join(builtin_names())})")
    out = {}
    for name in names:
        out[name] = ship(name, args.jobs)
        print(f"{name}: {out[name].get('decision', out[name].get('error'))}", file=sys.stderr, flush=True)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
