"""Whole-run views for the dashboard: every trial as columns, parameter importance, failures by reason."""

from __future__ import annotations

import math
from collections import Counter
from typing import Any

import numpy as np

from spinefarm.api.views import rung_lengths_s
from spinefarm.storage.base import BaseStorage

# Columns the dashboard plots and tabulates (parameters come separately, by name).
TABLE_COLUMNS = ("trial_id", "status", "reason", "phase", "parent", "objective", "distance_m", "speed_cm_s",
                 "work_j", "cot", "wall_time_s", "finished_at_unix_s", "verification", "verify_distance_m",
                 "worker_id", "pareto_front", "rung", "duration_s")
# Below this many finished trials a rank correlation per parameter is mostly noise: the page says so.
IMPORTANCE_MIN_TRIALS = 30
IMPORTANCE_TRIALS_PER_PARAM = 5


def _jsonable(a: np.ndarray) -> list[Any]:
    if a.dtype.kind == "S":
        return [x.decode("utf-8", "replace") for x in a.tolist()]
    if a.dtype.kind == "f":
        return [x if math.isfinite(x) else None for x in a.tolist()]
    return a.tolist()


def columns_view(storage: BaseStorage, with_params: bool = True) -> dict[str, Any]:
    """Every stored trial, one list per column (row i = trial i); NaN becomes null."""
    meta = storage.run_meta()
    cols = storage.columns()
    out: dict[str, Any] = {
        "run_id": meta.run_id, "n_trials": storage.n_trials(), "objective": meta.objective,
        "param_names": list(meta.param_names), "param_units": list(meta.param_units),
        "param_lows": list(meta.param_lows), "param_highs": list(meta.param_highs),
        "columns": {name: _jsonable(np.asarray(cols[name])) for name in TABLE_COLUMNS},
    }
    if with_params:
        params = np.asarray(cols["params"])
        out["params"] = {n: _jsonable(params[:, j]) for j, n in enumerate(meta.param_names)}
    return out


def _ranks(x: np.ndarray) -> np.ndarray:
    order = np.argsort(x, kind="stable")
    r = np.empty(len(x))
    r[order] = np.arange(len(x))
    # ties share their mean rank
    _, inv, counts = np.unique(x, return_inverse=True, return_counts=True)
    sums = np.bincount(inv, weights=r)
    return sums[inv] / counts[inv]


def importance(params_unit: np.ndarray, objective: np.ndarray) -> np.ndarray:
    """|Spearman rank correlation| of each parameter with the objective over finished trials: (n_params,).

    A cheap, model-free ranking that reads the same for 9 and for 200 parameters; 0 when undefined.
    """
    ok = np.isfinite(objective)
    n_params = params_unit.shape[1] if params_unit.ndim == 2 else 0
    if ok.sum() < 3 or n_params == 0:
        return np.zeros(n_params)
    y = _ranks(objective[ok])
    y = y - y.mean()
    x = np.apply_along_axis(_ranks, 0, params_unit[ok])
    x = x - x.mean(axis=0)
    den = np.sqrt((x * x).sum(axis=0) * (y * y).sum())
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = np.where(den > 0, (x * y[:, None]).sum(axis=0) / np.where(den > 0, den, 1.0), 0.0)
    return np.abs(rho)


def analysis_view(storage: BaseStorage) -> dict[str, Any]:
    meta = storage.run_meta()
    cols = storage.columns()
    status = np.asarray(cols["status"])
    # first-rung rows only: every parameter set once, at one trial length (a promoted row's longer trial
    # would rank the parameters that were promoted, not those that matter)
    complete = (status == b"complete") & (np.asarray(cols["rung"]) == 0)
    objective = np.where(complete, np.asarray(cols["objective"], dtype=float), np.nan)
    imp = importance(np.asarray(cols["params_unit"], dtype=float), objective)
    reasons = Counter(r.decode("utf-8", "replace").split(":")[0] or "unknown"
                      for r in np.asarray(cols["reason"])[status == b"failed"])
    n_used = int(np.isfinite(objective).sum())
    return {
        "pareto_front": storage.pareto_ids(),  # speed (max) against COT (min), as stored
        "importance": dict(zip(meta.param_names, (float(v) for v in imp), strict=True)),
        "importance_trials": n_used,
        "importance_min_trials": max(IMPORTANCE_MIN_TRIALS, IMPORTANCE_TRIALS_PER_PARAM * meta.n_params),
        # |rho| a parameter unrelated to the objective reaches by chance (about 2 standard errors)
        "importance_noise": 2.0 / math.sqrt(n_used - 1) if n_used > 1 else None,
        "failed_by_reason": dict(reasons.most_common()),
        "rungs": rungs_view(cols, rung_lengths_s(meta.settings)),
    }


def rungs_view(cols: Any, durations_s: list[float] | None) -> list[dict[str, Any]] | None:
    """Per rung of a multi-fidelity run: its trial length, trials, complete, promoted to the next rung,
    best and median distance, and for verified trials the median judge-to-screen distance ratio."""
    if not durations_s:
        return None
    rung = np.asarray(cols["rung"])
    parent = np.asarray(cols["parent"])
    status = np.asarray(cols["status"])
    dist = np.asarray(cols["distance_m"], dtype=float)
    judged = np.asarray(cols["verify_distance_m"], dtype=float)
    out = []
    for r, duration in enumerate(durations_s):
        here = rung == r
        done = here & (status == b"complete")
        promoted = int(np.isin(parent[rung == r + 1], np.flatnonzero(here)).sum())
        d = dist[done]
        ok = done & np.isfinite(judged) & (np.abs(dist) > 1e-9)
        ratio = judged[ok] / dist[ok]
        out.append({"rung": r, "duration_s": float(duration), "trials": int(here.sum()), "complete": int(done.sum()),
                    "promoted": promoted, "best_distance_m": float(d.max()) if d.size else None,
                    "median_distance_m": float(np.median(d)) if d.size else None,
                    "judged": int(ok.sum()), "judge_ratio_median": float(np.median(ratio)) if ratio.size else None})
    return out
