"""What the dashboard's contour costs the API: the kernel-weighted grid over n trials.

For each trial count and grid size, times `kernel_mean` (the work behind GET /runs/{id}/contour: two matrix
products of per-axis weights) against the direct sum over every (cell, trial) pair, best of R repeats, on
uniformly spread points; prints one JSON object per measurement (both times, their ratio, the largest relative
difference between the two grids) and a summary as its last line.

    python bench/contour_grid.py [--trials 300 2000 20000] [--grids 40 100] [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable

import numpy as np

from spinefarm.api.contour import bandwidth_for, kernel_mean


def direct(px: np.ndarray, py: np.ndarray, pz: np.ndarray, gx: np.ndarray, gy: np.ndarray, h: float) -> np.ndarray:
    """The reference: one exponential per (cell, trial) pair, cells in chunks."""
    cx, cy = (a.ravel() for a in np.meshgrid(gx, gy))
    out = np.empty(cx.size)
    step = max(1, 2_000_000 // px.size)
    for s in range(0, cx.size, step):
        w = np.exp(-0.5 * ((cx[s:s + step, None] - px) ** 2 + (cy[s:s + step, None] - py) ** 2) / h**2)
        out[s:s + step] = (w @ pz) / w.sum(axis=1)
    return out.reshape(gy.size, gx.size)


def best_of(fn: Callable[..., np.ndarray], args: tuple, repeats: int) -> tuple[float, np.ndarray]:
    best, out = float("inf"), np.zeros(0)
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn(*args)
        best = min(best, time.perf_counter() - t0)
    return best, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--trials", type=int, nargs="+", default=[300, 2000, 20000])
    ap.add_argument("--grids", type=int, nargs="+", default=[40, 100])
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    summary = []
    for n in args.trials:
        rng = np.random.default_rng(n)
        px, py, pz = rng.random(n), rng.random(n), rng.random(n)
        h = bandwidth_for(n)
        for grid in args.grids:
            g = (np.arange(grid) + 0.5) / grid
            fast_s, fast = best_of(kernel_mean, (px, py, pz, g, g, h), args.repeats)
            ref_s, ref = best_of(direct, (px, py, pz, g, g, h), 1)
            row = {"trials": n, "grid": grid, "kernel_mean_s": fast_s, "direct_s": ref_s,
                   "speedup": ref_s / fast_s, "max_rel_diff": float(np.nanmax(np.abs(fast - ref) / np.abs(ref)))}
            print(json.dumps(row), flush=True)
            summary.append(row)
    print(json.dumps({"summary": summary}))


if __name__ == "__main__":
    main()
