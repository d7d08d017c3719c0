"""The worker's Zenoh loop: stateless, pulls leased trials, returns results until acknowledged.

A worker declares a liveliness token (the coordinator re-issues its leases the moment it vanishes), finds a run
(given, or discovered on the network), asks its work queryable for a batch, fetches the run's config by hash once
(cached, so one worker can serve any run), runs each trial and resends results until the coordinator acknowledges
every one. An absent coordinator means back off and retry, never exit. The only worker module that imports zenoh.
"""

from __future__ import annotations

import enum
import json
import logging
import os
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import zenoh

from spinefarm.protocol import keys
from spinefarm.protocol.code_digest import code_digest
from spinefarm.protocol.envelope import decode_message, encode_message
from spinefarm.protocol.errors import ConfigError, MessageError, SpinefarmError
from spinefarm.protocol.results import TrialResult, fit_for_protocol
from spinefarm.protocol.run import RunConfig, WorkerProblem
from spinefarm.protocol.submissions import ResultAck, ResultSubmission, SubmittedResult
from spinefarm.protocol.work import RunInfo, TrialAssignment, WorkGrant, WorkRequest
from spinefarm.worker.service.assignment import available_engines, environment
from spinefarm.worker.service.connect import Connector, timed_out
from spinefarm.worker.service.evaluators import Evaluator, build_evaluator, failed_result, missing_config, sphere_result
from spinefarm.worker.service.pacing import Backoff, BatchSizer, default_worker_id, mark_ready
from spinefarm.worker.service.sandbox import MIN_LIMIT_S, SandboxStopped, TrialLimit, TrialSandbox

__all__ = ["Backoff", "BatchSizer", "WorkerService", "WorkerTimings", "ZenohAccess", "build_evaluator",
           "default_worker_id", "sphere_result"]
log = logging.getLogger("spinefarm.worker")
# A 2 s transport lease lets the coordinator notice a frozen (SIGSTOPped) worker in ~2 s, not 10 s.
WORKER_LEASE_MS = 2000
# With --exit-when-done: a run whose coordinator stays silent this long has ended (it may have ended
# while this worker was frozen or cut off, and then nobody is left to say "done").
COORDINATOR_TIMEOUT_S = 30.0


@dataclass(frozen=True)
class ZenohAccess:
    """How a worker reaches its coordinator: endpoints to connect to, endpoints to listen on (a peer), a Zenoh
    config file and a credentials file (protocol.credentials)."""

    connect: Sequence[str] = ()
    listen: Sequence[str] = ()
    config_file: str | Path | None = None
    credentials_file: str | Path | None = None

    def config(self) -> zenoh.Config:
        """Client of the coordinator/router at `connect`; multicast scouting off; short transport lease;
        with a credentials file it authenticates, and as a listening peer checks others."""
        try:
            conf = zenoh.Config.from_file(str(self.config_file)) if self.config_file else zenoh.Config()
        except Exception as exc:
            raise ConfigError(f"cannot read Zenoh config {self.config_file}: {exc}", expected="a JSON5 file") from exc
        conf.insert_json5("mode", json.dumps("peer" if self.listen else "client"))
        if self.connect:
            conf.insert_json5("connect/endpoints", json.dumps(list(self.connect)))
        if self.listen:
            conf.insert_json5("listen/endpoints", json.dumps(list(self.listen)))
        conf.insert_json5("scouting/multicast/enabled", "false")
        conf.insert_json5("transport/link/tx/lease", str(WORKER_LEASE_MS))
        if self.credentials_file is not None:
            from spinefarm.protocol.credentials import load_credentials

            for key, value in load_credentials(self.credentials_file).zenoh_settings(accept=bool(self.listen)).items():
                conf.insert_json5(key, value)
        return conf


@dataclass(frozen=True)
class WorkerTimings:
    """A worker's waits: a query's timeout, how often results are handed in, how long a worker with
    --exit-when-done idles before exiting, how long its coordinator may stay silent (the run has then ended),
    and the shortest wall-clock limit of a sandboxed trial."""

    query_timeout_s: float = 5.0
    submit_interval_s: float = 1.0
    idle_exit_s: float = 2.0
    coordinator_timeout_s: float = COORDINATOR_TIMEOUT_S
    min_trial_limit_s: float = MIN_LIMIT_S

    def __post_init__(self) -> None:
        for name, what in (("query_timeout_s", "query timeout"), ("submit_interval_s", "submit interval"),
                           ("coordinator_timeout_s", "coordinator timeout (--coordinator-timeout)"),
                           ("min_trial_limit_s", "minimum trial limit (--min-trial-limit)")):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{what} out of range", received=getattr(self, name), expected="seconds > 0")
        if not self.idle_exit_s >= 0:
            raise ConfigError("idle_exit_s out of range", received=self.idle_exit_s, expected="seconds >= 0")


class _Next(enum.Enum):
    """What the loop does after serving a run once."""

    AGAIN = "again"         # ask again at once
    BACK_OFF = "back off"   # wait, longer each time, then ask again
    RAN = "ran"             # trials ran: the back-off starts over
    EXIT = "exit"           # the worker's run is over


def _answer_identity(query: zenoh.Query) -> None:
    with query:
        query.reply(query.key_expr, b"")


class WorkerService:
    def __init__(self, access: ZenohAccess, *, run_id: str | None = None, worker_id: str | None = None,
                 batch: int | None = None, engines: tuple[str, ...] | None = None, exit_when_done: bool = False,
                 isolate: bool = True, timings: WorkerTimings | None = None) -> None:
        """access: where and how the worker reaches its coordinator; engines: the engines this worker offers
        (default: every installed one)."""
        self.worker_id = keys.check_worker_id(worker_id or default_worker_id())
        self.engines = available_engines(engines)
        self.environment = environment()
        self.code_digest = code_digest()
        self._holders: dict[str, str] = {}   # run id -> the coordinator session whose grants this worker follows
        self.run_id = keys.check_run_id(run_id) if run_id else None
        if batch is not None and not 1 <= batch <= 4096:
            raise ConfigError("batch out of range", received=batch, expected="1 <= batch <= 4096, or auto")
        self.batch = BatchSizer(batch)
        self.exit_when_done = exit_when_done
        self.isolate = isolate   # trials in a child process under a wall-clock limit (worker.service.sandbox)
        self.timings = timings or WorkerTimings()
        self._sandboxes: list[TrialSandbox] = []
        # SPINEFARM_ACK_LOG: one line per verdict received (run, trial, verdict, status, distance), for the
        # fault benches to count lost and duplicated results against what the coordinator acknowledged
        ack_log = os.environ.get("SPINEFARM_ACK_LOG")
        self._ack_log = open(ack_log, "a", buffering=1) if ack_log else None  # noqa: SIM115 (lives with the worker)
        self._last_heard = time.monotonic()   # the last reply from the current run's coordinator
        self.access = access
        access.config()  # fail fast on a bad config file
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
        for reply in session.get(key, payload=payload, timeout=self.timings.query_timeout_s):
            if reply.ok is None:
                log.warning("error reply on %s: %s", key, reply.err.payload.to_string()[:200])
                refused += not timed_out(reply)
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
            replies, refused = self._query(session, keys.config(run_id, config_hash), None, RunConfig)
            configs = [c for c in replies if c.config_hash() == config_hash]
            if not configs:  # not silently: the coordinator sees only a worker asking again without its trials
                log.error("%s", missing_config(run_id, config_hash, replies, refused, self.timings.query_timeout_s))
                return None
            try:
                self._evaluators[config_hash] = self._build(configs[0])
            except SandboxStopped:  # stopped while its trial process started: nothing wrong with the run
                return None
            except Exception as exc:  # a spec this worker cannot build: say so, serve nothing of it
                reason = str(exc) if isinstance(exc, SpinefarmError) else f"{type(exc).__name__}: {exc}"
                log.error("cannot run trials of run %s: %s", run_id, reason)
                self._report_problem(session, run_id, reason, lease)
                return None
        return self._evaluators[config_hash]

    def _build(self, config: RunConfig) -> Evaluator:
        """In a trial process with a wall-clock limit per trial (worker.service.sandbox), or in this one (the test
        objective without fault bands cannot hang: its microsecond trials skip the ~0.2 ms round trip)."""
        if not self.isolate or (config.is_test_objective and "poison" not in config.trial_config):
            return build_evaluator(config)
        sandbox = TrialSandbox(config, TrialLimit(self.timings.min_trial_limit_s), self.stop)
        self._sandboxes.append(sandbox)
        sandbox.start()
        return sandbox.run

    def _report_problem(self, session: zenoh.Session, run_id: str, reason: str, lease: TrialAssignment) -> None:
        self.unservable[run_id] = reason
        payload = encode_message(WorkerProblem(self.worker_id, reason, lease.trial_id, lease.lease_id))
        for _ in session.get(keys.problem(run_id), payload=payload, timeout=self.timings.query_timeout_s):
            pass

    def _apply(self, run_id: str, verdicts: tuple, coordinator: str) -> None:
        """Verdicts of run instance `coordinator`, taken for the results it leased, or for any once this worker serves
        it (the one that leased them is gone): a copy answering for the run cannot settle the holder's results."""
        pending = self._pending.get(run_id, {})
        serving = coordinator == self._holders.get(run_id, coordinator)
        for trial_id, verdict in verdicts:
            held = pending.get(trial_id)
            if held is None or not (serving or held.coordinator in ("", coordinator)):
                continue
            item = pending.pop(trial_id)
            if item is not None and verdict.value != "stored":
                log.info("trial %d of run %s not stored: %s", trial_id, run_id, verdict.value)
            if item is not None and self._ack_log is not None:
                self._ack_log.write(f"{run_id} {trial_id} {verdict.value} {item.result.status} "
                                    f"{item.result.distance_m!r}\n")
                self._ack_log.flush()

    def _submit(self, session: zenoh.Session, skip: str | None = None) -> bool:
        """Send every unacknowledged result (but those of run `skip`); True if nothing is left pending."""
        for run_id, pending in list(self._pending.items()):
            if not pending or run_id == skip:
                continue
            sub = ResultSubmission(self.worker_id, tuple(pending.values()))
            acks, refused = self._query(session, keys.results(run_id), encode_message(sub), ResultAck)
            for ack in acks:
                self._apply(run_id, ack.verdicts, ack.coordinator)
            if acks and run_id == self._current_run():
                self._last_heard = time.monotonic()
            if not acks and self.exit_when_done and run_id in self._done_runs:
                # Its coordinator said done or fell silent for --coordinator-timeout: nobody will take them.
                log.warning("run %s is over; %d results it never acknowledged are dropped", run_id, len(pending))
                pending.clear()
            elif refused and not acks:
                # The coordinator answered but refused the batch: resending it would loop forever.
                log.error("run %s refused %d results; dropping them (their leases will expire)", run_id, len(pending))
                pending.clear()
        return not any(pending for run_id, pending in self._pending.items() if run_id != skip)

    def _current_run(self) -> str | None:
        return self.run_id if self.run_id is not None else self._current

    def _silent(self) -> bool:
        """With --exit-when-done: the current run's coordinator has not answered for the timeout."""
        return self.exit_when_done and time.monotonic() - self._last_heard >= self.timings.coordinator_timeout_s

    def _run_one(self, evaluate: Evaluator, a: TrialAssignment) -> TrialResult | None:
        t0 = time.perf_counter()
        try:
            result = evaluate(a)
            if result is None:  # stopping: the trial was abandoned, its lease will expire
                return None
        except SpinefarmError as exc:
            result = failed_result(a, f"error: {exc}", time.perf_counter() - t0)
        except Exception as exc:  # a bug in one trial must not take the worker down
            log.exception("trial %d raised", a.trial_id)
            result = failed_result(a, f"error: {type(exc).__name__}: {exc}", time.perf_counter() - t0)
        return fit_for_protocol(replace(result, trial_id=a.trial_id, worker_id=self.worker_id, seed=a.seed))

    # --- main loop --------------------------------------------------------------------------------
    def run(self) -> int:
        # a config is used up by open: a fresh one for every attempt
        connector = Connector(lambda: zenoh.open(self.access.config()), zenoh.ZError, self.access.connect,
                              self.stop, exit_when_done=self.exit_when_done,
                              coordinator_timeout_s=self.timings.coordinator_timeout_s)
        session = connector.open()
        if session is None:
            self.exit_code = connector.exit_code or self.exit_code
            return self.exit_code
        token = session.liveliness().declare_token(keys.worker_token(self.worker_id))
        # the coordinator reads this session's id from the reply: the worker's identity for audits
        identity = session.declare_queryable(keys.worker_identity(self.worker_id), _answer_identity)
        mark_ready(self.worker_id)
        try:
            self._loop(session)
        finally:
            self._submit(session)
            for sandbox in self._sandboxes:
                sandbox.close()
            identity.undeclare()
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
                idle_s = time.monotonic() - idle_since
                if self.exit_when_done and self._done_runs and idle_s >= self.timings.idle_exit_s:
                    return
                self.stop.wait(backoff.next())
                continue
            idle_since = None
            step = self._serve(session, run_id)
            if step is _Next.EXIT:
                return
            if step is _Next.BACK_OFF:
                self.stop.wait(backoff.next())
            elif step is _Next.RAN:
                backoff.reset()

    def _serve(self, session: zenoh.Session, run_id: str) -> _Next:
        """One request for work in run `run_id` (this run's results ride along) and, if granted, its trials."""
        carried = tuple(self._pending.get(run_id, {}).values())
        req = encode_message(WorkRequest(self.worker_id, self.batch.size(), carried, self.engines, self.environment,
                                         self.code_digest))
        grants, refused = self._query(session, keys.work(run_id), req, WorkGrant)
        if not grants:
            return self._unanswered(session, run_id, resubmit=bool(refused and carried))
        self._last_heard = time.monotonic()
        grant = self._holder_grant(run_id, grants)
        self._apply(run_id, grant.verdicts, grant.coordinator)
        if grant.run_done:
            self._done_runs.add(run_id)
            # a worker given its run exits; a roaming one looks for another open run first
            return _Next.EXIT if self.exit_when_done and self.run_id is not None else _Next.AGAIN
        if not grant.assignments:
            self.stop.wait(grant.retry_after_s)
            return _Next.AGAIN
        evaluate = self._evaluator(session, run_id, grant.config_hash, grant.assignments[0])
        if evaluate is None:
            # Leases expire on the coordinator; nothing is lost by not running them.
            if run_id in self.unservable:
                self._done_runs.add(run_id)  # a roaming worker looks for another run
                if self.run_id is not None:
                    self.exit_code = 3
                    return _Next.EXIT
            return _Next.BACK_OFF
        self._run_batch(session, run_id, evaluate, grant)
        return _Next.RAN

    def _holder_grant(self, run_id: str, grants: list[WorkGrant]) -> WorkGrant:
        """The grant of the coordinator this worker served in the run while it answers (a second coordinator
        answering for the same run, a copy of its file, is not followed), else the first."""
        held = self._holders.get(run_id)
        grant = next((g for g in grants if g.coordinator == held), grants[0])
        if len(grants) > 1:
            log.warning("%d coordinators answer for run %s (%s); serving %s", len(grants), run_id,
                        ", ".join(g.coordinator for g in grants), grant.coordinator)
        self._holders[run_id] = grant.coordinator
        return grant

    def _unanswered(self, session: zenoh.Session, run_id: str, resubmit: bool) -> _Next:
        """No grant came back. A coordinator silent for its timeout has ended its run (--exit-when-done)."""
        if resubmit:
            self._submit(session)  # let the result path decide what to do with the refused request's results
        if not self._silent():
            return _Next.BACK_OFF
        log.warning("the coordinator of run %s has been silent for %.0f s: its run is over here",
                    run_id, time.monotonic() - self._last_heard)
        self._done_runs.add(run_id)
        if self.run_id is not None:
            return _Next.EXIT
        self._last_heard = time.monotonic()  # a roaming worker gives the next run its own time
        return _Next.AGAIN

    def _run_batch(self, session: zenoh.Session, run_id: str, evaluate: Evaluator, grant: WorkGrant) -> None:
        """Run a grant's trials in order, handing results in every submit_interval_s, each naming the instance
        that leased it."""
        pending = self._pending.setdefault(run_id, {})
        last_submit = time.monotonic()
        for a in grant.assignments:
            if self.stop.is_set() or self._silent():
                break  # a coordinator silent this long is gone: its leases are void
            t0 = time.perf_counter()
            result = self._run_one(evaluate, a)
            if result is None:
                break
            pending[a.trial_id] = SubmittedResult(a.lease_id, result, coordinator=grant.coordinator)
            self.batch.observe(time.perf_counter() - t0)
            self.trials_run += 1
            if time.monotonic() - last_submit >= self.timings.submit_interval_s:
                self._submit(session)
                last_submit = time.monotonic()
