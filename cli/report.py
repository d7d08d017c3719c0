"""The report a search prints when it ends: what it found, whether it holds, where it is, what to run next.

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


def _g(x: float, digits: int = 4) -> str:
    return f"{x:.{digits}g}" if math.isfinite(x) else "–"


def verdict_line(b: Any, judge: str | None) -> str:
    """How the best's re-simulation came out, in words."""
    if b.verification == "holds":
        speed = 100 * b.verify_distance_m / b.sim_time_s if b.sim_time_s > 0 else math.nan
        if judge:
            return f"verified in {judge}: {_g(b.verify_distance_m)} m, {_g(speed)} cm/s (the distance that counts)"
        return f"holds when re-simulated at a finer step: {_g(b.verify_distance_m)} m, {_g(speed)} cm/s"
    if b.verification == "not_reproduced":
        return f"NOT reproduced when re-simulated ({b.verify_reason or 'it moved differently'})"
    if b.verification == "pending":
        return "re-simulation pending (stopped before it finished)"
    return "not re-simulated"


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


def final_report(storage: Any, path: Path, *, judge: str | None, done: bool, verbose: bool = False) -> str:
    """The whole report as text (ends without a newline)."""
    meta = storage.run_meta()
    counts = storage.counts()
    finished = counts["complete"] + counts["failed"]
    physical = bool(meta.morphology_spec)
    lines = [f"{'search done' if done else 'search stopped'}: {finished} trials of {meta.morphology} "
             f"({counts['failed']} failed), run {meta.run_id}"]
    best = storage.best(1)
    if not best:
        lines.append("no complete trial yet")
    else:
        b = best[0]
        engine = f" in {b.engine} at {b.dt_s * 1e3:g} ms" if b.engine and math.isfinite(b.dt_s) else ""
        lines += [f"best trial {b.trial_id} ({b.phase}, {b.sim_time_s:g} s{engine})",
                  "  " + ("" if meta.objective == "distance" else f"{meta.objective} {_g(b.objective)} · ")
                  + f"distance {_g(b.distance_m)} m · speed {_g(b.speed_cm_s)} cm/s · COT {_g(b.cot)} · "
                  f"work {_g(b.work_j)} J",
                  f"  verdict: {verdict_line(b, judge)}"]
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
