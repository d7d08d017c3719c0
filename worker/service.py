"""The worker's Zenoh loop: stateless, pulls leased trials, returns results until acknowledged.

A worker declares a liveliness token (the coordinator re-issues its leases the moment it vanishes),
finds a run (given, or discovered on the network), asks its work queryable for a batch, fetches the
run's config by hash once (cached, so one worker can serve any run), runs each trial and resends
results until the coordinator acknowledges every one. An absent coordinator means back off and
retry, never exit. The only worker module that imports zenoh.
"""

from __future__ import annotations

import json
import logging
import os
import re
import socket
import threading
import time
import uuid
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
import zenoh
from spinefarm.protocol import keys
from spinefarm.protocol.errors import ConfigError, MessageError, RunMismatchError, SpinefarmError
from spinefarm.protocol.messages import (
    ResultAck,
    ResultSubmission,
    RunInfo,
    SubmittedResult,
    TrialAssignment,
    TrialResult,
    TrialStatus,
    WorkGrant,
    WorkRequest,
    decode_message,
    encode_message,
)
from spinefarm.protocol.params import ParamSpace
from spinefarm.protocol.run import RunConfig, WorkerProblem
from spinefarm.worker.tasks import available_engines, environment, physics_evaluator, with_fault

log = logging.getLogger("spinefarm.worker")
Evaluator = Callable[[TrialAssignment], TrialResult]
# A 2 s transport lease lets the coordinator notice a frozen (SIGSTOPped) worker in ~2 s, not 10 s.
WORKER_LEASE_MS = 2000
# With --exit-when-done: a run whose coordinator stays silent this long has ended (it may have ended
# while this worker was frozen or cut off, and then nobody is left to say "done").
COORDINATOR_TIMEOUT_S = 30.0
# A worker still without its coordinator after this long says so (then keeps trying).
UNREACHABLE_WARN_S = 3.0


def default_worker_id() -> str:
    host = "".join(ch if ch.isalnum() or ch in "-_." else "-" for ch in socket.gethostname())[:32]
    return f"{host or 'worker'}-{os.getpid()}-{uuid.uuid4().hex[:6]}"


def zenoh_config(connect: Sequence[str], listen: Sequence[str] = (),
                 config_file: str | Path | None = None, credentials_file: str | Path | None = None) -> zenoh.Config:
    """Client of the coordinator/router at `connect`; multicast scouting off; short transport lease;
    with a credentials file (protocol.credentials) it authenticates, and as a listening peer checks others."""
    try:
        conf = zenoh.Config.from_file(str(config_file)) if config_file else zenoh.Config()
    except Exception as exc:
        raise ConfigError(f"cannot read Zenoh config {config_file}: {exc}", expected="a JSON5 file") from exc
    conf.insert_json5("mode", json.dumps("peer" if listen else "client"))
    if connect:
        conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    if listen:
        conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("transport/link/tx/lease", str(WORKER_LEASE_MS))
    if credentials_file is not None:
        from spinefarm.protocol.credentials import load_credentials

        for key, value in load_credentials(credentials_file).zenoh_settings(accept=bool(listen)).items():
            conf.insert_json5(key, value)
    return conf


# --- evaluators ------------------------------------------------------------------------------------
def sphere_result(space: ParamSpace, a: TrialAssignment, delay_s: float = 0.0) -> TrialResult:
    """The built-in test objective: no physics, a smooth bowl with its top at x_i = 0.3.

    delay_s: wall time the trial takes (sleeping), to stand in for a physics trial in fault tests.
    """
    t0 = time.perf_counter()
    x = space.from_unit(np.asarray(a.params_unit))
    if delay_s > 0:
        time.sleep(delay_s)
    distance_m = float(len(x) - np.sum((x - 0.3) ** 2))
    work_j = float(np.sum(x**2))
    return TrialResult(TrialStatus.COMPLETE, "", distance_m, 100.0 * distance_m, 10.0 * distance_m, work_j,
                       work_j / (9.81 * distance_m) if distance_m > 0 else float("inf"), 10.0,
                       time.perf_counter() - t0, 1.0, a.seed)


def build_evaluator(config: RunConfig) -> Evaluator:
    """Turn a run object into a function of one assignment. The robot, its parameter space and the
    trial config are built from the run's own data (never looked up by name) and must reproduce the
    run's hashes; otherwise RunMismatchError says which part differs."""
    space = config.space()
    if config.is_test_objective:  # the test objective, see coordinator.problem
        if re.fullmatch(r"sphere(:\d+)?", config.morphology) is None:
            raise RunMismatchError("run has no morphology spec", received=config.morphology,
                                   expected="a morphology spec, or the test objective sphere[:N]")
        delay_s = float(config.trial_config.get("duration_s") or 0.0)
        return lambda a: with_fault(sphere_result(space, a, delay_s if a.duration_s is None else a.duration_s))
    from spinefarm.robot.morphology.model import Morphology
    from spinefarm.worker.trial import TrialConfig

    morphology = Morphology.from_dict(config.morphology_spec)
    trial_config = TrialConfig.from_dict(config.trial_config)
    built = {"spec_hash": morphology.spec_hash(),
             "space_hash": morphology.param_space(config.controller).space_hash(),
             "trial_config_hash": trial_config.config_hash()}
    for name, value in built.items():
        if getattr(config, name) != value:
            raise RunMismatchError(f"this worker cannot reproduce the run's {name} (a different software "
                                   "version?)", received=value, expected=getattr(config, name))
    return physics_evaluator(morphology, trial_config, config.controller, config.robust)


def failed_result(a: TrialAssignment, reason: str, wall_time_s: float) -> TrialResult:
    nan = float("nan")
    return TrialResult(TrialStatus.FAILED, reason[:150], nan, nan, nan, nan, nan, 0.0, wall_time_s, nan,
                       a.seed)


class Backoff:
    """Exponential wait between retries while the coordinator is absent."""

    def __init__(self, first_s: float = 0.05, max_s: float = 2.0) -> None:
        self.first_s, self.max_s, self._next = first_s, max_s, first_s

    def next(self) -> float:
        wait, self._next = self._next, min(self._next * 2, self.max_s)
        return wait

    def reset(self) -> None:
        self._next = self.first_s


class BatchSizer:
    """Trials to ask for: a fixed number, or (auto) about `target_s` of work by the mean trial time.

    Slow physics trials go one at a time (a lost worker strands little work); microsecond test trials
    go in large batches, so round trips do not dominate.
    """

    def __init__(self, fixed: int | None, target_s: float = 0.5, max_batch: int = 64) -> None:
        self.fixed, self.target_s, self.max_batch = fixed, target_s, max_batch
        self._mean_s: float | None = None

    def observe(self, wall_time_s: float) -> None:
        self._mean_s = wall_time_s if self._mean_s is None else 0.8 * self._mean_s + 0.2 * wall_time_s

    def size(self) -> int:
        if self.fixed is not None:
            return self.fixed
        if self._mean_s is None:
            return 1
        return max(1, min(self.max_batch, int(self.target_s / max(self._mean_s, 1e-6))))


class WorkerService:
    def __init__(self, *, connect: Sequence[str], run_id: str | None = None, worker_id: str | None = None,
                 batch: int | None = None, listen: Sequence[str] = (), zenoh_config_file: str | Path | None = None,
                 exit_when_done: bool = False, query_timeout_s: float = 5.0,
                 submit_interval_s: float = 1.0, idle_exit_s: float = 2.0,
                 coordinator_timeout_s: float = COORDINATOR_TIMEOUT_S,
                 credentials_file: str | Path | None = None, engines: tuple[str, ...] | None = None) -> None:
        """engines: the engines this worker offers (default: every installed one)."""
        self.worker_id = keys.check_worker_id(worker_id or default_worker_id())
        self.engines = available_engines(engines)
        self.environment = environment()
        self.run_id = keys.check_run_id(run_id) if run_id else None
        if batch is not None and not 1 <= batch <= 4096:
            raise ConfigError("batch out of range", received=batch, expected="1 <= batch <= 4096, or auto")
        self.batch = BatchSizer(batch)
        self.exit_when_done = exit_when_done
        self.query_timeout_s = query_timeout_s
        self.submit_interval_s = submit_interval_s
        self.idle_exit_s = idle_exit_s
        if not coordinator_timeout_s > 0:
            raise ConfigError("coordinator timeout out of range", received=coordinator_timeout_s,
                              expected="seconds > 0")
        self.coordinator_timeout_s = coordinator_timeout_s
        self._last_heard = time.monotonic()   # the last reply from the current run's coordinator
        self._conf_args = (tuple(connect), tuple(listen), zenoh_config_file, credentials_file)
        zenoh_config(*self._conf_args)  # fail fast on a bad config file
        self._evaluators: dict[str, Evaluator] = {}
        self._pending: dict[str, dict[int, SubmittedResult]] = {}   # run id -> trial id -> result
        self._done_runs: set[str] = set()
        self.unservable: dict[str, str] = {}   # run id -> why this worker cannot serve it
        self.exit_code = 0
        self._current: str | None = None   # the run a roaming worker serves now
        self.trials_run = 0
        self.stop = threading.Event()

    # --- requests ---------------------------------------------------------------------------------
    def _ask(self, session: zenoh.Session, key: str, payload: bytes | None, cls: type) -> list:
        """Replies to a query decoded as `cls`; malformed or error replies are logged and skipped."""
        return self._query(session, key, payload, cls)[0]

    def _query(self, session: zenoh.Session, key: str, payload: bytes | None, cls: type) -> tuple[list, int]:
        """(replies decoded as `cls`, number of replies that refused the request or were malformed)."""
        out, refused = [], 0
        for reply in session.get(key, payload=payload, timeout=self.query_timeout_s):
            if reply.ok is None:
                log.warning("error reply on %s", key)
                refused += 1
                continue
            try:
                out.append(decode_message(reply.ok.payload.to_bytes(), cls))
            except MessageError as exc:
                log.warning("ignored reply on %s: %s", key, exc)
                refused += 1
        return out, refused

    def _discover(self, session: zenoh.Session) -> str | None:
        """The run to work for: the given one, else the first open run announced on the network."""
        if self.run_id is not None:
            return self.run_id
        if self._current is not None and self._current not in self._done_runs:
            return self._current  # stay with a run until it says done: no discovery per batch
        infos = self._ask(session, keys.all_run_infos(), None, RunInfo)
        self._done_runs.update(i.run_id for i in infos if i.run_done)
        open_runs = sorted(i.run_id for i in infos if i.run_id not in self._done_runs)
        self._current = open_runs[0] if open_runs else None
        return self._current

    def _evaluator(self, session: zenoh.Session, run_id: str, config_hash: str,
                   lease: TrialAssignment) -> Evaluator | None:
        if config_hash not in self._evaluators:
            configs = self._ask(session, keys.config(run_id, config_hash), None, RunConfig)
            configs = [c for c in configs if c.config_hash() == config_hash]
            if not configs:
                return None
            try:
                self._evaluators[config_hash] = build_evaluator(configs[0])
            except Exception as exc:  # a spec this worker cannot build: say so, serve nothing of it
                reason = str(exc) if isinstance(exc, SpinefarmError) else f"{type(exc).__name__}: {exc}"
                log.error("cannot run trials of run %s: %s", run_id, reason)
                self._report_problem(session, run_id, reason, lease)
                return None
        return self._evaluators[config_hash]

    def _report_problem(self, session: zenoh.Session, run_id: str, reason: str, lease: TrialAssignment) -> None:
        self.unservable[run_id] = reason
        payload = encode_message(WorkerProblem(self.worker_id, reason, lease.trial_id, lease.lease_id))
        for _ in session.get(keys.problem(run_id), payload=payload, timeout=self.query_timeout_s):
            pass

    def _apply(self, run_id: str, verdicts: tuple) -> None:
        pending = self._pending.get(run_id, {})
        for trial_id, verdict in verdicts:
            if pending.pop(trial_id, None) is not None and verdict.value != "stored":
                log.info("trial %d of run %s not stored: %s", trial_id, run_id, verdict.value)

    def _submit(self, session: zenoh.Session, skip: str | None = None) -> bool:
        """Send every unacknowledged result (but those of run `skip`); True if nothing is left pending."""
        for run_id, pending in list(self._pending.items()):
            if not pending or run_id == skip:
                continue
            sub = ResultSubmission(self.worker_id, tuple(pending.values()))
            acks, refused = self._query(session, keys.results(run_id), encode_message(sub), ResultAck)
            for ack in acks:
                self._apply(run_id, ack.verdicts)
            if refused and not acks:
                # The coordinator answered but refused the batch: resending it would loop forever.
                log.error("run %s refused %d results; dropping them (their leases will expire)",
                          run_id, len(pending))
                pending.clear()
        return not any(pending for run_id, pending in self._pending.items() if run_id != skip)

    def _run_one(self, evaluate: Evaluator, a: TrialAssignment) -> TrialResult:
        t0 = time.perf_counter()
        try:
            result = evaluate(a)
        except SpinefarmError as exc:
            result = failed_result(a, f"error: {exc}", time.perf_counter() - t0)
        except Exception as exc:  # a bug in one trial must not take the worker down
            log.exception("trial %d raised", a.trial_id)
            result = failed_result(a, f"error: {type(exc).__name__}: {exc}", time.perf_counter() - t0)
        return replace(result, trial_id=a.trial_id, worker_id=self.worker_id, seed=a.seed)

    # --- main loop --------------------------------------------------------------------------------
    def _open(self) -> zenoh.Session | None:
        """A client session opens only once its router is reachable: retry with back-off until stopped."""
        backoff = Backoff(0.1, 2.0)
        since, told = time.monotonic(), False
        while not self.stop.is_set():
            try:
                return zenoh.open(zenoh_config(*self._conf_args))  # a config is used up by open
            except zenoh.ZError as exc:
                log.info("coordinator not reachable yet (%s); retrying", exc)
                if not told and time.monotonic() - since >= UNREACHABLE_WARN_S:
                    where = ", ".join(self._conf_args[0]) or "the configured endpoints"
                    log.warning("cannot reach a coordinator at %s; still trying (Ctrl-C to stop)", where)
                    told = True
                self.stop.wait(backoff.next())
        return None

    def run(self) -> int:
        session = self._open()
        if session is None:
            return 0
        token = session.liveliness().declare_token(keys.worker_token(self.worker_id))
        try:
            self._loop(session)
        finally:
            self._submit(session)
            token.undeclare()
            session.close()
        return self.exit_code

    def _loop(self, session: zenoh.Session) -> None:
        backoff = Backoff()
        idle_since: float | None = None
        self._last_heard = time.monotonic()
        while not self.stop.is_set():
            run_id = self._discover(session)
            # Results of other runs go on their own; this run's ride along with the next work request.
            if not self._submit(session, skip=run_id):
                self.stop.wait(backoff.next())
                continue
            if run_id is None:
                # Without a given run, "done" means no open run seen for a while, not one empty answer.
                idle_since = idle_since if idle_since is not None else time.monotonic()
                if self.exit_when_done and self._done_runs and time.monotonic() - idle_since >= self.idle_exit_s:
                    return
                self.stop.wait(backoff.next())
                continue
            idle_since = None
            carried = tuple(self._pending.get(run_id, {}).values())
            req = encode_message(WorkRequest(self.worker_id, self.batch.size(), carried, self.engines,
                                             self.environment))
            grants, refused = self._query(session, keys.work(run_id), req, WorkGrant)
            if not grants:
                if refused and carried:
                    self._submit(session)  # let the result path decide what to do with them
                if self.exit_when_done and time.monotonic() - self._last_heard >= self.coordinator_timeout_s:
                    log.warning("the coordinator of run %s has been silent for %.0f s: its run is over here",
                                run_id, time.monotonic() - self._last_heard)
                    self._done_runs.add(run_id)
                    if self.run_id is not None:
                        return
                    self._last_heard = time.monotonic()  # a roaming worker gives the next run its own time
                    continue
                self.stop.wait(backoff.next())
                continue
            self._last_heard = time.monotonic()
            grant = grants[0]
            self._apply(run_id, grant.verdicts)
            if grant.run_done:
                self._done_runs.add(run_id)
                if self.exit_when_done and self.run_id is not None:
                    return  # a roaming worker looks for another open run first
                continue
            if not grant.assignments:
                self.stop.wait(grant.retry_after_s)
                continue
            evaluate = self._evaluator(session, run_id, grant.config_hash, grant.assignments[0])
            if evaluate is None:
                # Leases expire on the coordinator; nothing is lost by not running them.
                if run_id in self.unservable:
                    self._done_runs.add(run_id)  # a roaming worker looks for another run
                    if self.run_id is not None:
                        self.exit_code = 3
                        return
                self.stop.wait(backoff.next())
                continue
            backoff.reset()
            pending = self._pending.setdefault(run_id, {})
            last_submit = time.monotonic()
            for a in grant.assignments:
                if self.stop.is_set():
                    break
                t0 = time.perf_counter()
                pending[a.trial_id] = SubmittedResult(a.lease_id, self._run_one(evaluate, a))
                self.batch.observe(time.perf_counter() - t0)
                self.trials_run += 1
                if time.monotonic() - last_submit >= self.submit_interval_s:
                    self._submit(session)
                    last_submit = time.monotonic()
