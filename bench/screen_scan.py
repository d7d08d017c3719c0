"""What the screen's own constants can close: a built-in's shipped calibration re-scored with MuJoCo's contact
constants moved.

The constants a screen fit may move (worker.tools.screen_fit.SCREEN_CONSTANTS: `mujoco.solref_time_s`,
`mujoco.solref_damping_ratio`) apply in MuJoCo only, so the judge's distances in a shipped calibration
(robot/calibrations/NAME.json: Bullet at the judge's step) stand for every value. The bench re-runs that
calibration's random gaits (seeds 1..gaits, its duration and settle) in MuJoCo at each value of a grid and
prints, per value, the agreement with the judge over those gaits (Spearman rho, top-10 overlap, the median
distance ratio over the gaits that move >= 1 cm in the judge) and the calibration's decision rule applied to
them. The first row, the model's own constants, must give the shipped MuJoCo distances back (`reproduces`).
Prints one JSON object.

    python bench/screen_scan.py tetraspine                       # solref_time_s and the damping ratio, 3 values each
    python bench/screen_scan.py ribbed --grid mujoco.solref_time_s=0.002,0.005,0.01,0.02 --jobs 2
"""

from __future__ import annotations

import argparse
import itertools
import json
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from spinefarm.worker.tools.calibrate import CalibrationSettings, _trial, agreement, clean, decide
from spinefarm.worker.tools.shipped_calibration import shipped_path

GRID = {"mujoco.solref_time_s": (0.002, 0.005, 0.02), "mujoco.solref_damping_ratio": (0.3, 1.0, 2.0)}


def _grid(specs: list[str]) -> dict[str, tuple[float, ...]]:
    if not specs:
        return GRID
    return {name: tuple(float(v) for v in values.split(",")) for name, values in (s.split("=", 1) for s in specs)}


def _score(judge: np.ndarray, screen: np.ndarray) -> dict:
    a = agreement(judge, screen)
    engine, why = decide(a)
    return {k: a[k] for k in ("spearman", "top_overlap", "top_k", "n_moving", "median_distance_ratio")} | {
        "decision": engine, "reason": why}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("robot", help="a built-in with a shipped calibration")
    ap.add_argument("--grid", action="append", default=[], metavar="NAME=V1,V2,...",
                    help="values of a MuJoCo-only constant (default: both contact constants, 3 values each)")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.worker.trial.simulation import random_unit_params

    t0 = time.time()
    cal = json.loads(shipped_path(args.robot).read_text())
    s = cal["settings"]
    n = int(s["gaits"])
    judge = np.array([np.nan if d is None else d for d in cal["distance_m"]["bullet"][:n]], dtype=float)
    shipped_screen = np.array([np.nan if d is None else d for d in cal["distance_m"]["mujoco"][:n]], dtype=float)
    morph = load_morphology(args.robot)
    gaits = [(tuple(random_unit_params(morph, seed, s["controller"])), seed) for seed in range(1, n + 1)]
    grid = _grid(args.grid)
    names = list(grid)
    points = [dict(zip(names, values, strict=True)) for values in itertools.product(*grid.values())]
    points.insert(0, {})  # the model's own constants first
    jobs = []
    for p in points:
        settings = CalibrationSettings(gaits=max(n, 3), search_trials=0, bests=0, duration_s=s["duration_s"],
                                       settle_s=s["settle_s"], controller=s["controller"], dt_s=s["dt_s"],
                                       auto_dt=s["auto_dt"], profile=tuple(sorted(p.items())))
        jobs += [(args.robot, u, seed, "mujoco", 1.0, settings) for u, seed in gaits]
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(_trial, jobs))
    dist = np.array([d for d, _ in rows]).reshape(len(points), n)
    own = dist[0]
    out = {"benchmark": "screen_scan", "robot": args.robot, "gaits": n, "duration_s": s["duration_s"],
           "settle_s": s["settle_s"], "judge": cal["reference"],
           "shipped_on_these_gaits": _score(judge, shipped_screen),
           "reproduces": bool(np.allclose(own, shipped_screen, rtol=1e-6, atol=2e-6, equal_nan=True)),
           "points": [{"constants": p, **_score(judge, d)} for p, d in zip(points, dist, strict=True)],
           "wall_s": round(time.time() - t0, 1)}
    print(json.dumps(clean(out)))


if __name__ == "__main__":
    main()
