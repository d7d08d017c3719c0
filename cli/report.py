"""The search's progress line and its final report of the best trial and the judge's verdict."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any


def progress(core: Any) -> tuple[int, int, str, str]:
    """(trials done, budget, what follows a progress bar, the whole line for a log)."""
    with core.lock:  # the transport threads write the table concurrently
        st = core.status()
        best = core.study.storage.best(1)
    done = st["trials_complete"] + st["trials_failed"]
    budget = st.get("trials_planned", st["trials_budget"])
    width = 24
    fill = int(width * done / max(budget, 1))
    best_s = f"{best[0].distance_m:.3f} m" if best else "-"
    eta = "-" if st["eta_s"] is None else f"{st['eta_s']:.0f}s"
    text = f"{st['trials_failed']} failed, {st['rate_trials_s']:.1f}/s, best {best_s}"
    return done, budget, text, (f"[{'#' * fill}{'.' * (width - fill)}] {done}/{budget} trials ({st['trials_failed']} "
                                f"failed)  {st['rate_trials_s']:.1f}/s  best {best_s}  ETA {eta}")


def verdict_text(b: Any, judge_engine: str | None) -> str:
    """What the judge found, in words: "holds" only within tolerance at the same engine; a cross-engine
    judgement says "judged in ENGINE" with both distances and their ratio."""
    if b.verification == "judged":
        speed = 100 * b.verify_distance_m / b.sim_time_s if b.sim_time_s else math.nan
        return (f"judged in {judge_engine or 'the judge engine'}: {b.verify_distance_m:.4g} m, {speed:.4g} cm/s "
                f"(the distance that counts; screen {b.distance_m:.4g} m, screen/judge ratio {b.judge_ratio:.3g})")
    if b.verification == "holds":
        return f"holds at a finer step ({b.verify_distance_m:.4g} m)"
    return {"pending": "verification pending", "": "not verified"}.get(b.verification, b.verification)


def describe_best(core: Any, path: Path) -> str:
    storage = core.study.storage
    best = storage.best(1)
    lines = []
    choice = storage.run_meta().settings.engine_choice
    if choice is not None:
        lines.append(choice.describe())
    if core.drift:
        lines.append(f"the judge raised the screen's fidelity: {core.drift}")
    audit = core.status()["audit"]
    if any(v for k, v in audit.items() if k.startswith("audits_")):
        lines.append("audits: " + ", ".join(f"{k[7:]} {v}" for k, v in audit.items() if k.startswith("audits_")))
    if not best:
        return "\n".join([*lines, f"no complete trial yet; file {path}"])
    b = best[0]
    meta = storage.run_meta()
    params = ", ".join(f"{n}={v:.4g}{(' ' + u) if u and u != '1' else ''}"
                       for n, v, u in zip(meta.param_names, b.params, meta.param_units, strict=True))
    engine = f" in {b.engine} at {b.dt_s * 1e3:g} ms" if b.engine else ""
    lines.append(f"best trial {b.trial_id} ({b.phase}, {b.sim_time_s:g} s{engine}): objective {b.objective:.4g}, "
                 f"distance {b.distance_m:.4g} m, speed {b.speed_cm_s:.4g} cm/s, work {b.work_j:.4g} J, "
                 f"COT {b.cot:.4g}; {verdict_text(b, meta.settings.judge.rung.engine)}")
    lines.append(f"  params: {params}\nfile: {path}")
    return "\n".join(lines)
