"""The search's progress line and the report it prints when it ends: what it found, whether it holds, where
it is, what to run next.

Parameters are left to `--verbose` and to the gait file (`spinefarm export RUN.h5 --gait best.json`): a
controller has up to a few hundred of them, which no one reads on a terminal.
"""

from __future__ import annotations

import math
import shlex
import sys
import threading
from pathlib import Path
from typing import Any

from spinefarm.storage.codesign_coverage import run_coverage
from spinefarm.storage.evaluations import judged_cot
from spinefarm.storage.model_spread import model_spread, spread_text
from spinefarm.storage.ranking import counted_distance_m, evaluation_counts, judged_speed_cm_s

DISTANCE_OBJECTIVES = ("distance", "speed")  # an objective that is a score part already, shown as that part


def progress(core: Any) -> tuple[int, int, str, str]:
    """(parameter sets done, sets asked for, what follows a progress bar, the whole line for a log). Sets and
    evaluations are counted apart: a multi-fidelity run evaluates a set more than once."""
    with core.lock:  # the transport threads write the table concurrently
        st = core.status()
        best, pending = core.study.storage.reported_best(1)
    done, budget, evaluations = st["parameter_sets_done"], st["trials_budget"], st["evaluations_done"]
    width = 24
    fill = int(width * done / max(budget, 1))
    best_s = "-"
    if best:
        b = best[0]
        counted_m, judged = _counted(b), b.verification in ("holds", "moved", "judged")
        best_s = f"{counted_m:.3f} m" + (" judged" if judged else "")
        if core.study.storage.run_meta().objective not in DISTANCE_OBJECTIVES:  # what a COT objective trades
            speed, cot = _judge_figures(core.study.storage, b, counted_m, 3) if judged \
                else (b.speed_cm_s, _g(b.cot, 3))
            best_s += f" ({_g(speed, 3)} cm/s, COT {cot})"
    if pending is not None:   # better, but no other identity has reproduced it yet: not the best
        best_s += f" ({_counted(pending):.3f} m pending audit)"
    eta = "-" if st["eta_s"] is None else f"{st['eta_s']:.0f}s"
    text = f"{evaluations} evaluations, {st['trials_failed']} failed, {st['rate_trials_s']:.1f}/s, best {best_s}"
    return done, budget, text, (f"[{'#' * fill}{'.' * (width - fill)}] {done}/{budget} parameter sets, "
                                f"{evaluations} evaluations ({st['trials_failed']} failed)  "
                                f"{st['rate_trials_s']:.1f}/s  best {best_s}  ETA {eta}")


def verdict_text(b: Any, judge_engine: str | None) -> str:
    """What the judge found, in words: "holds" only within tolerance at the same engine; a cross-engine
    judgement says "judged in ENGINE" with both distances and their ratio."""
    if b.verification == "judged":
        speed = judged_speed_cm_s(b.verify_distance_m, b.sim_time_s)
        return (f"judged in {judge_engine or 'the judge engine'}: {b.verify_distance_m:.4g} m, {speed:.4g} cm/s "
                f"(the distance that counts; screen {b.distance_m:.4g} m, screen/judge ratio {b.judge_ratio:.3g})")
    if b.verification == "holds":
        return f"holds at a finer step ({b.verify_distance_m:.4g} m)"
    if b.verification == "moved":  # kept: the judged distance is the one that counts
        return f"{b.verify_reason.split(' (')[0]}: {b.verify_distance_m:.4g} m judged (the distance that counts; " \
               f"screen {b.distance_m:.4g} m)"
    if b.verification == "diverged":
        return f"diverged in the judge's run ({b.verify_reason})"
    return {"pending": "verification pending", "": "not verified"}.get(b.verification, b.verification)


def _counted(b: Any) -> float:
    return counted_distance_m(b.verification, b.distance_m, b.verify_distance_m)


def _g(x: float, digits: int = 4) -> str:
    return f"{x:.{digits}g}" if math.isfinite(x) else "–"


def next_commands(path: Path, physical: bool, resumable: bool, best_id: int | None) -> list[tuple[str, str]]:
    """(command, what it does) for a person to copy."""
    f = shlex.quote(str(path))
    out = [(f"spinefarm api {f}", "the dashboard: plots, every trial, the gait moving")]
    if physical and best_id is not None:
        out += [(f"spinefarm render --run {f} --video best.mp4", "watch the best gait (or best.gif)"),
                (f"spinefarm export {f} --gait best.json", "its parameters as a file for `spinefarm trial --params`"),
                (f"spinefarm trial --run {f}", "run the best again")]
    if resumable:
        out.append((f"spinefarm search --resume {f}", "continue where it stopped"))
    return out


def describe_best(core: Any, path: Path, verbose: bool = False) -> str:
    """The final report of a search's coordinator core."""
    storage = core.study.storage
    notes = []
    if core.drift:
        notes.append(f"the judge raised the screen's fidelity: {core.drift}")
    audit = core.status()["audit"]
    if any(v for k, v in audit.items() if k.startswith("audits_")):
        notes.append("audits: " + ", ".join(f"{k[7:]} {v}" for k, v in audit.items() if k.startswith("audits_")))
    best, pending = storage.reported_best(1)
    if pending is not None and pending.trial_id in core.unaudited:
        notes.append(f"trial {pending.trial_id}, better than the best: {core.unaudited[pending.trial_id]}; its audit "
                     "stays pending (a resume with another worker identity runs it)")
    verdict = verdict_text(best[0], storage.run_meta().settings.judge.rung.engine) if best else ""
    return final_report(storage, path, verdict=verdict, done=core.done, verbose=verbose, notes=tuple(notes))


def _objective_text(meta: Any, b: Any) -> str:
    """The objective ahead of the score's parts, named so that it is not mistaken for one of them: a robust
    run's is a statistic over episodes, and its parts are the episodes' medians."""
    if meta.run.get("robust"):
        from spinefarm.protocol.robust import RobustSpec

        spec = RobustSpec.from_dict(meta.run["robust"])
        return (f"objective {_g(b.objective)} ({spec.statistic} of {meta.objective} over "
                f"{spec.episodes_for(b.duration_s)} episodes) · medians: ")
    return "" if meta.objective in DISTANCE_OBJECTIVES else f"{meta.objective} {_g(b.objective)} · "


def _judge_figures(storage: Any, b: Any, counted_m: float, digits: int = 4) -> tuple[float, str]:
    """(a judged set's speed in cm/s: its judged distance over the simulated time, its COT as shown: the judge's
    run's from its evaluation row, or why there is none, e.g. "not measured" in a file from before that column)."""
    cot, why = judged_cot(storage.evaluations(), b.trial_id)
    return judged_speed_cm_s(counted_m, b.sim_time_s), f"{_g(cot, digits)} (judged)" if cot is not None else str(why)


def _cost_text(storage: Any, b: Any, counted_m: float, judged: bool) -> str:
    """Speed and COT of the best: a judged set's the judge's, the screen's beside them."""
    if not judged:
        return f"speed {_g(b.speed_cm_s)} cm/s · COT {_g(b.cot)} · work {_g(b.work_j)} J"
    speed, cot = _judge_figures(storage, b, counted_m)
    return f"speed {_g(speed)} cm/s (judged) · COT {cot} · screen's COT {_g(b.cot)}, work {_g(b.work_j)} J"


def final_report(storage: Any, path: Path, *, verdict: str, done: bool, verbose: bool = False,
                 notes: tuple[str, ...] = ()) -> str:
    """The whole report as text (ends without a newline); verdict: the judge's word on the best, notes: lines
    on how the search went (drift, audits)."""
    meta = storage.run_meta()
    counts = storage.counts()
    n = evaluation_counts(storage.columns(), storage.evaluations())
    physical = bool(meta.morphology_spec)
    lines = [f"{'search done' if done else 'search stopped'}: {n['parameter_sets_done']} parameter sets, "
             f"{n['evaluations_done']} evaluations of {meta.morphology} ({counts['failed']} failed), run {meta.run_id}"]
    lines += list(notes)
    if meta.settings.engine_choice is not None:  # how --engine auto chose the tier
        lines.append(meta.settings.engine_choice.describe())
    coverage = run_coverage(meta, storage.columns()) if meta.run.get("body") else None
    if coverage is not None:  # a co-designed run: the calibration covers its base body, the judge the rest
        lines.append(coverage["statement"])
    best, pending = storage.reported_best(1)
    if pending is not None:
        lines.append(f"pending audit: trial {pending.trial_id}, distance {_g(_counted(pending))} m, is better than "
                     "any audited set; it is reported best once another worker identity's audit agrees")
    if not best:
        lines.append("no audited best yet" if pending is not None else "no complete trial yet")
    else:
        b = best[0]
        engine = f" in {b.engine} at {b.dt_s * 1e3:g} ms" if b.engine and math.isfinite(b.dt_s) else ""
        counted_m = counted_distance_m(b.verification, b.distance_m, b.verify_distance_m)
        judged = b.verification in ("holds", "moved", "judged")
        lines += [f"best trial {b.trial_id} ({b.phase}, {b.sim_time_s:g} s{engine})",
                  "  " + _objective_text(meta, b) + f"distance {_g(counted_m)} m" + (" (judged)" if judged else "")
                  + " · " + _cost_text(storage, b, counted_m, judged),
                  f"  verdict: {verdict}"]
        if (spread := model_spread(storage, b)) is not None:  # the judged best in the other engine too
            lines.append("  " + spread_text(spread))
        if verbose:
            lines.append(f"  parameters ({meta.n_params}):")
            width = max(len(n) for n in meta.param_names) if meta.param_names else 0
            lines += [f"    {n:<{width}}  {v:.6g}{(' ' + u) if u and u != '1' else ''}"
                      for n, v, u in zip(meta.param_names, b.params, meta.param_units, strict=True)]
        else:
            lines.append(f"  {meta.n_params} parameters: --verbose prints them, `spinefarm export "
                         f"{shlex.quote(str(path))} --gait best.json` writes them")
    lines.append(f"file: {path}")
    cmds = next_commands(path, physical, not done, best[0].trial_id if best else None)
    width = max(len(c) for c, _ in cmds)
    lines.append("next:")
    lines += [f"  {c:<{width}}   # {what}" for c, what in cmds]
    return "\n".join(lines)


def serve_until_stopped(api: tuple[Any, threading.Thread, int], host: str, stopped: threading.Event) -> None:
    """`search --serve`: the dashboard stays up over the finished run file until Ctrl-C (or SIGTERM)."""
    server, thread, port = api
    print(f"the dashboard stays up on http://{host}:{port}/ until Ctrl-C", file=sys.stderr, flush=True)
    while not stopped.wait(0.25) and thread.is_alive():
        pass
    server.should_exit = True
    thread.join(5)
