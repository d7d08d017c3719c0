"""Model spread of a judged best: the judge's distance beside the other engine's second opinion.

A judged best is also run in the engine that does not judge, at a converged step: an evaluation of kind
"opinion" in the evaluations table (storage.evaluations), linked to the row it checked. Read from the stored
rows alone, the spread is both distances and their ratio (other / judge), shown beside each engine's step
error (the median relative change of a gait's distance at half the step, from the run's calibration,
`engine_choice.tiers`): a ratio further from 1 than the step errors is the models' difference, not the steps'.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from spinefarm.protocol.states import EvaluationKind
from spinefarm.storage.evaluations import latest
from spinefarm.storage.schema import json_number


def _side(cols: dict[str, np.ndarray], i: int, engine: str, dt_s: float | None) -> dict[str, Any]:
    stored_dt = float(cols["dt_s"][i])
    return {"engine": cols["engine"][i].decode() or engine,
            "dt_s": stored_dt if math.isfinite(stored_dt) else dt_s,
            "distance_m": json_number(float(cols["distance_m"][i])), "cot": json_number(float(cols["cot"][i])),
            "status": cols["status"][i].decode(),
            "reason": cols["reason"][i].decode() or None, "wall_time_s": json_number(float(cols["wall_time_s"][i])),
            "worker_id": cols["worker_id"][i].decode() or None}


def model_spread(storage: Any, rec: Any, cols: dict[str, np.ndarray] | None = None) -> dict[str, Any] | None:
    """{judge, other, ratio, step_error} for trial record `rec`, or None when no opinion row checked it.
    judge and other: {engine, dt_s, distance_m, cot, status, reason, wall_time_s, worker_id} (the judge's from its
    evaluation row, else from the verdict's columns); ratio: other / judge (None when either is missing or the
    judge's is 0); step_error: {engine: median relative change at half the step} from the run's calibration
    (empty when the run chose no engine by calibrating). cols: the evaluations table when read already."""
    cols = storage.evaluations() if cols is None else cols
    mine = latest(cols, rec.trial_id, EvaluationKind.OPINION)
    if mine is None:
        return None
    meta = storage.run_meta()
    rung = meta.settings.judge.rung
    run_engine = (meta.trial_config or {}).get("engine") or rec.engine or ""
    judge_engine = rung.engine or run_engine
    j = latest(cols, rec.trial_id, EvaluationKind.JUDGE)
    judge = _side(cols, j, judge_engine, rung.dt_s) if j is not None else {
        "engine": judge_engine, "dt_s": rung.dt_s, "distance_m": json_number(rec.verify_distance_m),
        "cot": None, "status": None, "reason": None, "wall_time_s": None, "worker_id": None}
    other = _side(cols, mine, "", None)
    d_judge, d_other = judge["distance_m"], other["distance_m"]
    ratio = d_other / d_judge if d_judge and d_other is not None and other["status"] == "complete" else None
    choice = meta.settings.engine_choice
    tiers = choice.tiers if choice is not None else {}
    return {"judge": judge, "other": other, "ratio": ratio,
            "step_error": {t: v.get("step_error") for t, v in tiers.items()}}


def spread_text(spread: dict[str, Any]) -> str:
    """One line: both distances, their ratio and the step errors."""
    def side(s: dict[str, Any]) -> str:
        step = f" at {1e3 * s['dt_s']:g} ms" if s["dt_s"] else ""
        if s["distance_m"] is None or s["status"] not in (None, "complete"):
            return f"{s['engine']}{step} failed ({s['reason'] or 'no distance'})"
        return f"{s['engine']}{step} {s['distance_m']:.4g} m"

    ratio = "-" if spread["ratio"] is None else f"{spread['ratio']:.3g}"
    first = [spread["judge"]["engine"], spread["other"]["engine"]]  # in the order the distances are
    order = sorted(spread["step_error"], key=lambda t: first.index(t) if t in first else len(first))
    errors = ", ".join(f"{t} {100 * e:.2g} %" for t in order if (e := spread["step_error"][t]) is not None)
    return (f"model spread: judge {side(spread['judge'])}, other engine {side(spread['other'])}, ratio {ratio}"
            + (f" (step error {errors})" if errors else " (no calibration: step errors unknown)"))
