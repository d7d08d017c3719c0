"""The objective over two parameters on a grid: a kernel-weighted mean of the finished trials around each cell."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from spinefarm.api.errors import InvalidQuery
from spinefarm.protocol.states import REFUTED_VERDICTS
from spinefarm.storage.base import BaseStorage

GRID_MIN, GRID_MAX = 2, 200
CONTOUR_VALUES = ("objective", "distance_m", "speed_cm_s", "cot")
# cells whose summed weight is below this are farther than ~4 bandwidths from every trial: no estimate
MIN_WEIGHT = math.exp(-8.0)
# kernel weights held at once (cells along one axis × trials), to bound memory on runs of many trials
CHUNK_ELEMENTS = 4_000_000


def bandwidth_for(n_points: int) -> float:
    """Kernel width as a fraction of each axis' range: about the spacing of n points spread over the square."""
    return float(np.clip(1.0 / math.sqrt(max(n_points, 1)), 0.03, 0.25))


def _weights(centres: np.ndarray, at: np.ndarray, h: float) -> np.ndarray:
    """exp(-d²/2h²) per (centre, trial), 0 below e^-40: a product of two such weights far below a kept cell's
    total (> MIN_WEIGHT) changes no digit, and zeros keep the products out of slow subnormal arithmetic."""
    arg = -0.5 * ((centres[:, None] - at[None, :]) / h) ** 2
    return np.where(arg > -40.0, np.exp(np.maximum(arg, -40.0)), 0.0)


def kernel_mean(px: np.ndarray, py: np.ndarray, pz: np.ndarray, gx: np.ndarray, gy: np.ndarray,
                h: float) -> np.ndarray:
    """Gaussian-weighted mean of pz at every (gx[j], gy[i]); inputs in [0, 1] units. Returns (len(gy), len(gx)),
    NaN where no trial is near.

    The 2-D Gaussian is the product of one along x and one along y, so the sums over trials are two matrix
    products: exponentials per (cell column, trial) and (cell row, trial), not per (cell, trial).
    """
    total = np.zeros((gy.size, gx.size))
    sums = np.zeros((gy.size, gx.size))
    step = max(1, CHUNK_ELEMENTS // max(gx.size, gy.size, 1))
    for start in range(0, px.size, step):
        sl = slice(start, start + step)
        wx = _weights(gx, px[sl], h)  # (len(gx), trials)
        wy = _weights(gy, py[sl], h)  # (len(gy), trials)
        total += wy @ wx.T
        sums += wy @ (wx * pz[None, sl]).T
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(total > MIN_WEIGHT, sums / np.where(total > 0, total, 1.0), np.nan)


def _param_index(names: list[str], which: str, name: str) -> int:
    if name not in names:
        shown = ", ".join(names[:12]) + (f", … ({len(names)} in all)" if len(names) > 12 else "")
        raise InvalidQuery(f"{which}: no such parameter in this run", received=name, expected=f"one of {shown}")
    return names.index(name)


def contour_view(storage: BaseStorage, x: str, y: str, grid: int, value: str = "objective",
                 rung: int = 0) -> dict[str, Any]:
    """The grid of `value` over parameters x and y (physical units), and the trials it is made from: those of
    one rung of a multi-fidelity run (default the first, where every parameter set is scored once at one trial
    length; mixing rungs would mix 3 s distances with 30 s ones)."""
    meta = storage.run_meta()
    n_rungs = len(meta.settings.ladder)
    if not 0 <= rung < n_rungs:
        raise InvalidQuery("rung out of range", received=rung,
                           expected=f"an integer in [0, {n_rungs - 1}] (this run has {n_rungs} rung(s))")
    names = list(meta.param_names)
    jx, jy = _param_index(names, "x", x), _param_index(names, "y", y)
    if jx == jy:
        raise InvalidQuery("x and y name the same parameter", received=x, expected="two different parameters")
    if not GRID_MIN <= grid <= GRID_MAX:
        raise InvalidQuery("grid out of range", received=grid, expected=f"an integer in [{GRID_MIN}, {GRID_MAX}]")
    if value not in CONTOUR_VALUES:
        raise InvalidQuery("value: not a score the grid can show", received=value,
                           expected="one of " + ", ".join(CONTOUR_VALUES))
    lo = np.array([meta.param_lows[jx], meta.param_lows[jy]], dtype=float)
    hi = np.array([meta.param_highs[jx], meta.param_highs[jy]], dtype=float)
    span = np.where(hi > lo, hi - lo, 1.0)
    n = storage.n_trials()
    if n:
        cols = storage.columns()
        params = np.asarray(cols["params"], dtype=float)
        z = np.asarray(cols[value], dtype=float)
        used = (np.asarray(cols["status"]) == b"complete") & np.isfinite(z) \
            & ~np.isin(cols["verification"], REFUTED_VERDICTS) & (np.asarray(cols["rung"]) == rung)
        ids = np.flatnonzero(used)
        px, py, pz = params[ids, jx], params[ids, jy], z[ids]
    else:
        ids, px, py, pz = (np.zeros(0, dtype=int), np.zeros(0), np.zeros(0), np.zeros(0))
    centres = (np.arange(grid) + 0.5) / grid  # cell centres in [0, 1] of each range
    h = bandwidth_for(ids.size)
    values = kernel_mean((px - lo[0]) / span[0], (py - lo[1]) / span[1], pz, centres, centres, h) if ids.size \
        else np.full((grid, grid), np.nan)
    return {
        "run_id": meta.run_id, "x": x, "y": y, "value": value,
        "value_name": meta.objective if value == "objective" else value,
        "grid": grid, "bandwidth": h, "rung": rung, "rungs": n_rungs,
        "method": "Gaussian-kernel mean of the complete trials, bandwidth as a fraction of each parameter's range",
        "x_range": [float(lo[0]), float(hi[0])], "y_range": [float(lo[1]), float(hi[1])],
        "x_centres": (lo[0] + centres * span[0]).tolist(), "y_centres": (lo[1] + centres * span[1]).tolist(),
        # z[i][j]: at y_centres[i], x_centres[j]; null where no trial is near
        "z": [[v if math.isfinite(v) else None for v in row] for row in values.tolist()],
        "points": {"trial_id": ids.tolist(), "x": px.tolist(), "y": py.tolist(), "value": pz.tolist()},
    }
