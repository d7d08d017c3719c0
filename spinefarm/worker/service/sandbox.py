"""Trials run in a child process under a wall-clock limit: a hung or crashing simulator costs one trial,
not the worker.

A hung pybullet or MuJoCo call sits in C: no signal handler or thread can end it inside the process that
made it. So the worker keeps one long-lived child per run (spawned, so no Zenoh thread is forked) that
builds the run's evaluator once (robot, set-up cache, compiled kernels) and runs trials handed to it
over a pipe; the worker waits for each result at most the trial's limit, then SIGKILLs the child (which
ends any call, also in a SIGSTOPped child), reports the trial `timeout: ...`, and starts a fresh child
for the next one. A child that dies mid-trial (a segfault) reports it `crashed: ...`. Both go back to
the coordinator, which re-issues the trial until it has done this on 3 workers (coordinator.core).

The limit (TrialLimit): max(min_s, factor x the measured wall seconds per simulated second x the
trial's simulated seconds), measured per kind of task (task, engine, step, perturbed, length); before a
task of its kind has completed here, first_factor x the larger of min_s and the slowest measured rate scaled
to its step (a first trial may compile kernels; a first judge runs a finer step in another engine).
The child asks the kernel for SIGKILL when the worker dies.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import signal
import time
from collections.abc import Hashable
from dataclasses import replace
from multiprocessing.connection import Connection
from threading import Event

from spinefarm.protocol.errors import SpinefarmError
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.run import RunConfig
from spinefarm.protocol.work import TrialAssignment
from spinefarm.worker.service.evaluators import build_evaluator, failed_result
from spinefarm.worker.service.parent_death import die_with_parent

MIN_LIMIT_S = 30.0
LIMIT_FACTOR = 8.0
FIRST_FACTOR = 10.0
START_TIMEOUT_S = 300.0    # building the evaluator in a fresh child (imports, compiled kernels from cache)
_POLL_S = 0.25             # how often a wait looks at the worker's stop flag
# A trial process dead of these was most likely signalled with its worker's whole process group (a batch
# system ending the job, a hang-up): if the worker stops within STOP_GRACE_S too, that is no crash.
_STOP_SIGNALS = (signal.SIGTERM, signal.SIGHUP)
STOP_GRACE_S = 2.0
START_ATTEMPTS = 3  # starts of a trial process killed by a signal before it was ready, before that is a problem
RETRIED_REASONS = ("timeout:", "crashed:")   # coordinator.core re-issues these (kept in step)


class TrialLimit:
    """Wall-clock limit of a trial from its simulated length and the cost measured on this worker, kept per kind
    of task: a rung's screen, a judge at a finer step in another engine and a perturbed re-run cost per simulated
    second what the others do not (a MuJoCo 2 ms screen and a Bullet 0.25 ms judge differ ~30x), so one
    measured rate would time out every judge."""

    def __init__(self, min_s: float = MIN_LIMIT_S, factor: float = LIMIT_FACTOR,
                 first_factor: float = FIRST_FACTOR) -> None:
        if not (min_s > 0 and factor >= 1 and first_factor >= 1):
            raise ValueError(f"trial limit settings out of range: min_s={min_s}, factor={factor}, "
                             f"first_factor={first_factor} (expected min_s > 0, factors >= 1)")
        self.min_s, self.factor, self.first_factor = min_s, factor, first_factor
        # measured wall s per simulated s (slowest-leaning mean) and the step it ran at, per kind of task
        self._rates: dict[Hashable, tuple[float, float | None]] = {}

    def observe(self, wall_time_s: float, sim_time_s: float, kind: Hashable = None, dt_s: float | None = None) -> None:
        if not (wall_time_s > 0 and sim_time_s > 0):
            return
        r = wall_time_s / sim_time_s
        w = self._rates.get(kind, (None, None))[0]
        self._rates[kind] = (r if w is None else max(0.8 * w + 0.2 * r, 0.5 * w), dt_s)

    def limit_s(self, sim_s: float, kind: Hashable = None, dt_s: float | None = None) -> float:
        """A kind measured here: factor x its rate x sim_s. A kind not yet measured (a first trial, or the first
        judge of a run): first_factor x the larger of min_s and the slowest measured rate scaled to this step."""
        if not sim_s > 0:
            return self.first_factor * self.min_s
        if kind in self._rates:
            return max(self.min_s, self.factor * self._rates[kind][0] * sim_s)
        guesses = [r * (max(1.0, dt / dt_s) if dt and dt_s else 1.0) * sim_s for r, dt in self._rates.values()]
        return self.first_factor * max([self.min_s, *guesses])


def simulated_s(config: RunConfig, a: TrialAssignment) -> float:
    """Simulated seconds the trial asks for (settle phase included)."""
    tc = config.trial_config
    duration = a.duration_s if a.duration_s is not None else float(tc.get("duration_s") or 0.0)
    settle = a.fidelity.settle_s if a.fidelity is not None and a.fidelity.settle_s is not None else None
    return duration + float(tc.get("settle_s") or 0.0 if settle is None else settle)


def simulated_here_s(sim_s: float, result: TrialResult) -> float:
    """The simulated seconds a trial of sim_s ran in this worker: a promotion that went on from its last rung's kept
    end (worker.trial.continued) ran only the rest, and the limit's rate is per second simulated."""
    return sim_s - float(result.extras.get("continued_s", 0.0))


def task_kind(config: RunConfig, a: TrialAssignment) -> tuple[Hashable, float | None]:
    """What a trial's cost per simulated second depends on (its task, engine, step, perturbed re-run and length:
    robust episodes may grow by rung) and its step, where known."""
    f = a.fidelity
    step = f.dt_s if f is not None and f.dt_s is not None else config.trial_config.get("dt_s")
    dt_s = float(step) if isinstance(step, int | float) and not isinstance(step, bool) else None
    kind = (None, None, False, None) if f is None else (f.task, f.engine, f.perturb, f.dt_s)
    return (*kind, a.duration_s), dt_s


def _child(conn: Connection, config: RunConfig) -> None:
    die_with_parent(signal.SIGKILL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the worker's to handle
    try:
        _serve(conn, config)
    except (BrokenPipeError, ConnectionResetError):
        return  # the worker died or gave up on this process (e.g. killed while it started): nobody to answer


def _serve(conn: Connection, config: RunConfig) -> None:
    try:
        evaluate = build_evaluator(config)
    except Exception as exc:
        conn.send(("problem", str(exc) if isinstance(exc, SpinefarmError) else f"{type(exc).__name__}: {exc}"))
        return
    conn.send(("ready", None))
    while True:
        try:
            a = conn.recv()
        except (EOFError, OSError):
            return
        try:
            conn.send(("ok", evaluate(a)))
        except SpinefarmError as exc:
            conn.send(("error", f"error: {exc}"))
        except Exception as exc:  # a bug in one trial must not take the child down
            conn.send(("error", f"error: {type(exc).__name__}: {exc}"))


class SandboxProblem(SpinefarmError):
    """The run's evaluator cannot be built here (the worker reports it as a WorkerProblem)."""


class SandboxStopped(Exception):
    """The worker stopped while its trial process was starting: no problem of the run's (nothing to report)."""


class _KilledAtStart(Exception):
    """The trial process died of a signal before it was ready (its words: the signal)."""


class TrialSandbox:
    """One child process running one run's trials; `run(a)` never takes longer than the trial's limit."""

    def __init__(self, config: RunConfig, limit: TrialLimit | None = None, stop: Event | None = None) -> None:
        self.config = config
        self.limit = limit or TrialLimit()
        self.stop = stop or Event()
        self._proc: mp.process.BaseProcess | None = None
        self._conn: Connection | None = None
        self.restarts = 0

    def start(self) -> None:
        """Start the child and wait until its evaluator is built; SandboxProblem if it cannot be. A child
        killed by a signal while it starts (the OOM killer, a stray kill) is started again, up to
        START_ATTEMPTS times in all: only a problem that repeats is the run's."""
        for attempt in range(1, START_ATTEMPTS + 1):
            try:
                self._start_once()
                return
            except _KilledAtStart as killed:
                if attempt == START_ATTEMPTS:
                    raise SandboxProblem(f"the trial process did not start ({killed}, {attempt} times)") from None

    def _start_once(self) -> None:
        ctx = mp.get_context("spawn")
        parent, child = ctx.Pipe()
        self._proc = ctx.Process(target=_child, args=(child, self.config), daemon=True, name="spinefarm-trials")
        self._proc.start()
        child.close()
        self._conn = parent
        msg = self._wait(START_TIMEOUT_S)
        if (msg is None and self.stop.is_set()) or (msg == ("eof", None) and self._stopped_with_worker()):
            self._kill()
            raise SandboxStopped()
        kind, value = msg or ("problem", "")
        if kind != "ready":
            value = None if kind == "eof" else value
            code = self._kill()
            if kind == "eof" and code is not None and code < 0:
                raise _KilledAtStart(_exit_text(code))
            raise SandboxProblem(value or f"the trial process did not start ({_exit_text(code)})")

    def _wait(self, timeout_s: float) -> tuple[str, object] | None:
        """The child's next message within timeout_s; ("eof", None) if it died; None on timeout or stop."""
        end = time.monotonic() + timeout_s
        assert self._conn is not None
        while not self.stop.is_set():
            try:
                if self._conn.poll(max(0.0, min(_POLL_S, end - time.monotonic()))):
                    return self._conn.recv()
            except (EOFError, OSError):
                return ("eof", None)
            if time.monotonic() >= end:
                return None
        return None

    def _kill(self) -> int | None:
        proc, self._proc = self._proc, None
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        if proc is None:
            return None
        if proc.is_alive():
            proc.kill()
        proc.join(10)
        return proc.exitcode

    def run(self, a: TrialAssignment) -> TrialResult | None:
        """The trial's result (timeout and crash as failed results); None if the worker is stopping."""
        if self._proc is None or not self._proc.is_alive():
            self._kill()
            self.start()
        sim_s = simulated_s(self.config, a)
        kind, dt_s = task_kind(self.config, a)
        limit_s = self.limit.limit_s(sim_s, kind, dt_s)
        t0 = time.perf_counter()
        assert self._conn is not None
        self._conn.send(a)
        msg = self._wait(limit_s)
        wall = time.perf_counter() - t0
        if msg is None and self.stop.is_set():
            self._kill()
            return None
        if msg is not None and msg[0] == "eof" and self._stopped_with_worker():
            return None
        if msg is None or msg[0] == "eof":
            code = self._kill()
            self.restarts += 1
            reason = (f"timeout: no result within its {limit_s:.3g} s wall-clock limit ({sim_s:g} s simulated)"
                      if msg is None else f"crashed: the trial process died ({_exit_text(code)})")
            result = failed_result(a, reason, wall)
        elif msg[0] == "ok":
            result = msg[1]
            if result.ok:
                self.limit.observe(result.wall_time_s, simulated_here_s(sim_s, result), kind, dt_s)
        else:
            result = failed_result(a, str(msg[1]), wall)
        return replace(result, extras={**result.extras, "time_limit_s": limit_s})

    def _stopped_with_worker(self) -> bool:
        """Whether the child died of a stop signal and this worker is stopping too (then the trial is
        abandoned: its lease expires and it is re-issued, with no strike against it)."""
        proc = self._proc
        if proc is None:
            return False
        proc.join(1.0)
        if proc.exitcode not in [-int(sig) for sig in _STOP_SIGNALS] or not self.stop.wait(STOP_GRACE_S):
            return False
        self._kill()
        return True

    def close(self) -> None:
        self._kill()


def _exit_text(code: int | None) -> str:
    if code is not None and code < 0:
        with contextlib.suppress(ValueError):
            return f"signal {signal.Signals(-code).name}"
    return f"exit code {code}"
