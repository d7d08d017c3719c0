"""How far a co-designed run's fast tier is vouched for (docs/codesign.md): the calibration (or fit) that chose
the screen ran on the file's own body, the base body; on the bodies the search samples it holds only as far as
the judge's screen-to-judge ratios on those bodies confirm, and the drift rule watches those ratios as in any
run. Read from the run's stored settings and columns alone, so the report, the status and /runs/ID/meta say
the same."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np


def _text(value: Any) -> str:
    return value.decode() if isinstance(value, bytes) else str(value)


def _calibration(engine_choice: Mapping[str, Any] | None, engine: str | None) -> str:
    if engine_choice is None:
        return f"none: the engine was given ({engine or 'the default'}), no calibration chose the screen"
    fitted = " (with its fitted screen)" if engine_choice.get("screen_fit") else ""
    return f"the base body only: calibrated on spec {engine_choice.get('spec_hash') or '?'}{fitted}"


def coverage(run: Mapping[str, Any], engine_choice: Mapping[str, Any] | None, drift: float | None,
             cols: Mapping[str, np.ndarray]) -> dict[str, Any] | None:
    """None for a fixed body; else what the calibration covers and the judge's ratios on sampled bodies.

    run: the stored run object (RunConfig.to_dict(): its `body` search, spec_hash of the base body, trial
    config); engine_choice: how `--engine auto` chose the tier (None: the engine was given); drift: the judge's
    band (--judge-drift), None for a run without a judge; cols: the run's columns (body_hash, judge_ratio)."""
    if not run.get("body"):
        return None
    base = str(run.get("spec_hash") or "")
    hashes = np.array([_text(h) for h in cols.get("body_hash", [])], dtype=object)
    ratio = np.asarray(cols.get("judge_ratio", []), dtype=float)
    sampled = (hashes != base) & (hashes != "")
    judged = np.isfinite(ratio) & sampled if ratio.size else np.zeros(0, dtype=bool)
    r = ratio[judged] if ratio.size else ratio
    ratios = {"judged": int(judged.sum()), "median": float(np.median(r)) if r.size else None,
              "min": float(r.min()) if r.size else None, "max": float(r.max()) if r.size else None}
    engine = (run.get("trial_config") or {}).get("engine")
    out = {"base_body_hash": base, "calibration_covers": _calibration(engine_choice, engine),
           "sampled_bodies": int(len(set(hashes[sampled]))), "judge_ratios_on_sampled_bodies": ratios,
           "drift_band": None if drift is None else [1 - drift, 1 + drift]}
    out["statement"] = statement(out)
    return out


def statement(c: Mapping[str, Any]) -> str:
    """One line: the calibration covers the base body; the judge's ratios speak for the sampled bodies."""
    r = c["judge_ratios_on_sampled_bodies"]
    seen = (f"{r['judged']} judged, median screen-to-judge ratio {r['median']:.3g} ({r['min']:.3g}-{r['max']:.3g})"
            if r["judged"] else "none judged yet")
    head = (f"co-designed: the calibration covers {c['calibration_covers']}; its {c['sampled_bodies']} sampled "
            f"bodies hold only as far as the judge's ratios confirm")
    if c["drift_band"] is None:
        return head + " (the run has no judge: nothing confirms them)"
    lo, hi = c["drift_band"]
    return head + f" ({seen}); the drift rule watches them as in any run (band [{lo:.3g}, {hi:.3g}])"


def run_coverage(meta: Any, cols: Mapping[str, np.ndarray]) -> dict[str, Any] | None:
    """coverage() of a stored run: meta is its RunMeta (run object and typed settings)."""
    choice = meta.settings.engine_choice
    judge = meta.settings.judge
    return coverage(meta.run, None if choice is None else choice.to_dict(),
                    judge.drift if judge.enabled else None, cols)
