"""Fitting recorded motion, measured.

--identify: recordings made with our own model (tetraspine-ntrt, 2 random gaits of 2 s, every step recorded)
with five constants changed by +-30 %; the fit (spinefarm.worker.fit) starts from the model's own values and
must recover each within 5 %, or say which constants the recordings cannot tell apart and why. Prints one JSON
object: {"constants": {NAME: {"true", "fitted", "rel_error", "identifiable", "why"?}}, ...}.

    python bench/fit.py --identify [--engine mujoco] [--evaluations 200] [--restarts 3]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

# the model's values (tetraspine-ntrt) changed by +-30 %
CHANGED = {"ground_friction": 1.3, "rod_friction": 0.7, "string_stiffness_n_per_m": 1.3,
           "string_damping_n_s_per_m": 0.7, "rod_density_kg_per_cm3": 0.7}


def identify_bench(args: argparse.Namespace) -> dict:
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.robot.profile import current_value
    from spinefarm.worker.fit.identify import identify

    morph = load_morphology(args.robot)
    true = {n: current_value(morph, n, args.engine, {}) * f for n, f in CHANGED.items()}
    t0 = time.time()
    out = identify(morph, args.engine, true, seeds=args.seeds, duration_s=args.duration, window_s=args.window,
                   restarts=args.restarts, evaluations=args.evaluations)
    return {**out, "wall_s": time.time() - t0,
            "command": "python bench/fit.py --identify " + " ".join(sys.argv[2:])}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--identify", action="store_true", help="recover known constants from our own recordings")
    ap.add_argument("--robot", default="tetraspine-ntrt")
    ap.add_argument("--engine", default="mujoco")
    ap.add_argument("--seeds", type=int, nargs="+", default=[3, 5])
    ap.add_argument("--duration", type=float, default=2.0)
    ap.add_argument("--window", type=float, default=0.2)
    ap.add_argument("--restarts", type=int, default=3)
    ap.add_argument("--evaluations", type=int, default=200)
    args = ap.parse_args()
    if not args.identify:
        ap.error("say what to measure: --identify")
    print(json.dumps(identify_bench(args)))


if __name__ == "__main__":
    main()
