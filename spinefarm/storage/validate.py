"""Validation of every stored row before a run is resumed: a damaged file is refused, never continued.

A resumed run trusts its file completely (the sampler's centre is the best stored row; waiting rows
are issued again), so garbage there would be searched from, re-issued for ever or reported as best.
Checks per row: trial id = row number, a known status and phase, finite parameters inside the unit
cube and inside the stored bounds, the seed the run derives for that trial, a parent that exists, and
finite scores for complete rows. The error lists the first offending rows and what each one holds.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

import numpy as np

from spinefarm.protocol.errors import StorageError
from spinefarm.storage.schema import AUDITS, PHASE_PATTERN, STATUSES, VERIFICATIONS, RunMeta

_SHOWN = 5
_FINITE_WHEN_COMPLETE = ("objective", "distance_m", "ntrt_distance_cm", "speed_cm_s", "work_j")


def row_problems(meta: RunMeta, cols: dict[str, np.ndarray],
                 seed_of: Callable[[int, np.ndarray], np.ndarray] | None = None) -> dict[str, np.ndarray]:
    """Check name -> boolean mask (n,) of rows that fail it."""
    n = len(cols["trial_id"])
    ids = np.arange(n)
    status = cols["status"]
    complete = status == b"complete"
    unit = cols["params_unit"].reshape(n, meta.n_params)
    params = cols["params"].reshape(n, meta.n_params)
    lows, highs = np.asarray(meta.param_lows, dtype=float), np.asarray(meta.param_highs, dtype=float)
    span = np.maximum(np.abs(highs - lows), 1.0)
    phase = re.compile(PHASE_PATTERN)
    out = {
        "trial id is not the row number": cols["trial_id"] != ids,
        f"status not one of {', '.join(STATUSES)}": ~np.isin(status, [s.encode() for s in STATUSES]),
        "phase is not a short lower-case name": ~np.array([bool(phase.fullmatch(bytes(p))) for p in cols["phase"]],
                                                          dtype=bool),
        "verification verdict unknown": ~np.isin(cols["verification"], [v.encode() for v in VERIFICATIONS]),
        "audit state unknown": ~np.isin(cols["audit"], [a.encode() for a in AUDITS]),
        "unit parameters not finite or outside [0, 1]": ~np.all(np.isfinite(unit) & (unit >= 0) & (unit <= 1),
                                                                axis=1),
        "parameters outside the stored bounds": ~np.all(
            np.isfinite(params) & (params >= lows - 1e-9 * span) & (params <= highs + 1e-9 * span), axis=1),
        "parent is not an earlier trial": (cols["parent"] < -1) | (cols["parent"] >= ids),
    }
    if seed_of is not None:
        out["seed is not the one the run derives"] = cols["seed"] != seed_of(meta.seed, ids)
    for name in _FINITE_WHEN_COMPLETE:
        out[f"complete with a non-finite {name}"] = complete & ~np.isfinite(cols[name])
    return out


def validate_rows(path: str | Path, meta: RunMeta, cols: dict[str, np.ndarray],
                  seed_of: Callable[[int, np.ndarray], np.ndarray] | None = None) -> None:
    """Raise StorageError naming the bad rows (and why) unless every row passes."""
    problems = {k: np.flatnonzero(m) for k, m in row_problems(meta, cols, seed_of).items() if m.any()}
    if not problems:
        return
    bad = np.unique(np.concatenate(list(problems.values())))
    lines = [f"{what}: {len(rows)} rows (first: {', '.join(_show(cols, int(r)) for r in rows[:_SHOWN])})"
             for what, rows in problems.items()]
    raise StorageError(f"cannot resume {path}: {len(bad)} of {len(cols['trial_id'])} stored rows are invalid; "
                       + "; ".join(lines),
                       expected="an undamaged run file (nothing was changed; export the good rows with "
                                "`spinefarm export --csv` and start a new run)")


def _show(cols: dict[str, np.ndarray], r: int) -> str:
    status = bytes(cols["status"][r])[:16]
    return (f"row {r} [id {int(cols['trial_id'][r])}, status {status!r}, seed {int(cols['seed'][r])}, "
            f"distance {float(cols['distance_m'][r]):.4g} m]")
