"""CoordinatorCore: the run's state machine behind the transport (bytes in, bytes out).

Every handler decodes and validates its message, so a malformed or foreign message is logged and answered with an
error, never raised into the transport and never touching what is stored. One lock serialises the handlers, which
the transport may call from several threads.

A result is acknowledged ("stored") only after the storage has written it out and synced it to the disk (`commit`:
one fsync per request, however many results it carries), so the file holds every acknowledged result after a killed
coordinator, a crashed machine or a power cut. A failed write or sync (disk full, I/O error) sets `write_failure`
(and `failure`): from then on no handler answers (workers keep their unacknowledged results and retry), and the
process running the core stops with that reason.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from spinefarm.coordinator.ladder.checks import Checks
from spinefarm.coordinator.ladder.keys import KINDS, check_key, split_key
from spinefarm.coordinator.ladder.ladder import Ladder
from spinefarm.coordinator.ladder.rungs import Asker
from spinefarm.coordinator.peers import PeerBook
from spinefarm.coordinator.scheduler import Scheduler
from spinefarm.coordinator.study import Study
from spinefarm.protocol.envelope import decode_message, encode, encode_message
from spinefarm.protocol.errors import MessageError
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.run import RunConfig, WorkerProblem
from spinefarm.protocol.states import TrialStatus
from spinefarm.protocol.submissions import ResultAck, ResultSubmission, Verdict
from spinefarm.protocol.work import RunInfo, WorkGrant, WorkRequest

RETRIED_REASONS = ("timeout:", "crashed:")   # failures on a worker that another worker may not have

log = logging.getLogger("spinefarm.coordinator")
_RATE_WINDOW_S = 30.0
# Idle workers together ask about this often: 450 idle workers asking every 0.5 s (900 requests a second) held
# every grant back by about a second at the end of bench/scale.py's 500-worker run
IDLE_ASKS_PER_S = 100.0


class CoordinatorCore:
    def __init__(self, study: Study, scheduler: Scheduler, run_config: RunConfig,
                 clock: Callable[[], float] = time.monotonic, idle_retry_s: float = 0.5,
                 checks: Checks | None = None, peers: PeerBook | None = None) -> None:
        self.study = study
        self.scheduler = scheduler
        self.run_config = run_config
        self.config_hash = run_config.config_hash()
        self.clock = clock
        self.idle_retry_s = idle_retry_s
        self.lock = threading.RLock()
        self.rejected_messages = 0
        self.forged_results = 0  # results quoting a lease this worker was never given
        self.foreign_results = 0  # results leased by another instance of the run (refused unread)
        self.dropped_results: dict[str, int] = {v.value: 0 for v in Verdict if v != Verdict.STORED}
        self._finish_times: deque[float] = deque()
        self.told_done: set[str] = set()  # workers that have been told the budget is met
        self.write_failure: str | None = None  # why the run file can no longer be written
        self.started_s = clock()
        self._config_payload = encode_message(run_config)
        self.peers = peers or PeerBook(quarantine=False)
        self.peers.rebuild(study.storage)
        # every evaluation is the ladder's: a restart issues again whatever the file says is pending
        self.ladder = Ladder(study, scheduler, checks or Checks(study.storage, study.trial_scheduler.settings, None,
                                                                study.seed, False), self.peers, clock)
        self.failure: str | None = None  # why the run cannot go on (a worker cannot build it)
        self.unservable_workers: dict[str, str] = {}  # worker -> why it cannot serve this run (others do)
        self.code_digest: str | None = None   # the run's simulating code: workers of another are left out
        self.holder = ""   # the run instance serving (the file's, see service.start), named in grants and results
        self.claims: dict[str, str] = {}   # other coordinators that claimed this run -> what was done

    @property
    def drift(self) -> str | None:
        """Why the ladder raised the screen's fidelity (None: it did not)."""
        return self.ladder.drift

    @property
    def unaudited(self) -> dict[int, str]:
        """Rows whose audit stays pending, and why."""
        return self.ladder.unaudited

    def identified(self, worker_id: str, sessions: set[str]) -> None:
        """The Zenoh sessions that answered for `worker_id` (the service's probe)."""
        with self.lock:
            self.ladder.quarantine(self.peers.identified(worker_id, sessions), "its session's other worker was")

    @property
    def run_id(self) -> str:
        return self.run_config.run_id

    @property
    def search_done(self) -> bool:
        """Every evaluation of the search is stored (checks may still be running)."""
        with self.lock:  # a multi-fidelity "done" reads several columns the transport threads write
            return self.study.done

    @property
    def done(self) -> bool:
        """The search is done and so are its checks (judge, audits, referees, opinion)."""
        with self.lock:
            return self.ladder.done

    def pending_check_kinds(self) -> set[str]:
        """What still runs after the search: "judge", "audit", "referee", "opinion" (empty: nothing)."""
        with self.lock:
            return {split_key(k)[0] for k in self.ladder.checks.pending}

    # --- handlers (transport calls these) ---------------------------------------------------------
    def _error(self, what: str, exc: MessageError) -> bytes:
        self.rejected_messages += 1
        log.warning("ignored malformed %s: %s", what, str(exc))  # a string: keep no traceback alive
        return encode("error", exc.to_detail())

    def commit(self) -> bool:
        """Write out and sync everything stored so far; False (and `write_failure` set) if the storage cannot."""
        if self.write_failure is not None:
            return False
        with self.lock:
            try:
                self.study.storage.flush()
            except Exception as exc:  # disk full, I/O error, a file system shut down: stop taking work
                self.write_failure = str(exc)
                self.failure = self.failure or self.write_failure
                log.error("stopping: %s", self.write_failure)
                return False
        return True

    def handle_work(self, payload: bytes) -> bytes | None:
        """A WorkGrant (or an error); None: no answer, the run file can no longer be written."""
        req = self._receive(payload, WorkRequest, "work request")
        if not isinstance(req, WorkRequest):
            return req
        with self.lock:
            self.peers.heard(req.worker_id, req.engines, req.environment)
            self._check_code(req.worker_id, req.code_digest)
            verdicts = self._settle_all(req.worker_id, req.results)  # before "done": they may finish it
            if verdicts is None:
                return None
            self._take_back_unreported(req.worker_id)
            if self.study.done:
                self.ladder.drop_unservable()
            if self.done:
                self.told_done.add(req.worker_id)
                return encode_message(WorkGrant(self.run_id, self.config_hash, (), self._idle_retry(), True,
                                                verdicts, self.holder))
            if self.peers.is_quarantined(req.worker_id) or req.worker_id in self.unservable_workers:
                return encode_message(WorkGrant(self.run_id, self.config_hash, (), self._idle_retry(), False,
                                                verdicts, self.holder))
            # a promotion goes first to the worker that ran its last rung, which may go on from that rung's end
            asker = Asker(req.worker_id, lambda w: self.scheduler.speaking(w) and not self.peers.is_quarantined(w)) \
                if self.ladder.continue_rungs else None
            leases = self.scheduler.grant(req.worker_id, req.capacity, lambda: self.study.ask(asker),
                                          self.ladder.eligible)
            self._store_given_up()
            assignments = tuple(self.ladder.assignment(ls, self.clock()) for ls in leases)
            retry = 0.0 if assignments else self._idle_retry()
        return encode_message(WorkGrant(self.run_id, self.config_hash, assignments, retry, False, verdicts,
                                        self.holder))

    def _idle_retry(self) -> float:
        """How long a worker given nothing waits before it asks again: longer with more live workers (lock held)."""
        alive = sum(1 for w in self.scheduler.workers.values() if w.alive)
        return max(self.idle_retry_s, alive / IDLE_ASKS_PER_S)

    def _check_code(self, worker_id: str, digest: str | None) -> None:
        """A worker whose simulating code is not the run's is left out: its distances would differ, unmarked
        (lock held)."""
        if self.code_digest is None or digest == self.code_digest or worker_id in self.unservable_workers:
            return
        said = f"digest {digest[:12]}" if digest else "no code digest (an older install)"
        self._leave_out(worker_id, f"runs other simulating code: {said}, the run's is {self.code_digest[:12]}")

    def _take_back_unreported(self, worker_id: str) -> None:
        """A worker asks without results of trials it holds: a grant it never received (its query timed out, the reply
        was lost) or could not run (no run config): issued again at once, no attempt counted; after max_unreported
        asks in a row they go to other workers (scheduler)."""
        lost, barred = self.scheduler.take_back_unreported(worker_id)
        if barred:
            log.warning("worker %s asked for work %d times in a row without trial(s) %s it was granted: it does not "
                        "get or cannot run its grants; they go to other workers", worker_id,
                        self.scheduler.max_unreported, ", ".join(map(str, lost[:8])))
        elif lost:
            log.warning("worker %s asked for work without the %d trial(s) it holds (%s): a grant it never got; "
                        "issued again", worker_id, len(lost), ", ".join(map(str, lost[:8])))

    def handle_results(self, payload: bytes) -> bytes | None:
        """A ResultAck (or an error); None: no answer, the run file can no longer be written."""
        sub = self._receive(payload, ResultSubmission, "result submission")
        if not isinstance(sub, ResultSubmission):
            return sub
        with self.lock:
            verdicts = self._settle_all(sub.worker_id, sub.items)
        return None if verdicts is None else encode_message(ResultAck(verdicts, self.holder))

    def _receive(self, payload: bytes, cls: type, what: str) -> Any:
        """The decoded message; else the answer to give: an error for a malformed one, None (no answer) once
        the run file can no longer be written."""
        if self.write_failure is not None:
            return None
        try:
            return decode_message(payload, cls)
        except MessageError as exc:
            return self._error(what, exc)

    def _settle_all(self, worker_id: str, items: tuple) -> tuple[tuple[int, Verdict], ...] | None:
        """Verdicts for submitted results, written out (caller holds the lock); None if the run file can no
        longer be written."""
        self.scheduler.contact(worker_id)
        verdicts = []
        foreign = [item.coordinator for item in items if item.coordinator != self.holder]
        if foreign:  # leased by another instance of the run (before a restart, or a copy): nothing of them stored
            self.foreign_results += len(foreign)
            log.warning("worker %s returned %d result(s) leased by run instance %s, not this one (%s): refused",
                        worker_id, len(foreign), ", ".join(f or "(none named)" for f in sorted(set(foreign))),
                        self.holder)
        for item in items:
            if item.coordinator != self.holder:
                verdicts.append((item.result.trial_id, Verdict.STALE))
                self.dropped_results[Verdict.STALE.value] += 1
                continue
            v = self._settle(worker_id, item.lease_id, item.result, item.unreadable)
            verdicts.append((item.result.trial_id, v))
            if v == Verdict.STORED:
                self._finish_times.append(self.clock())
            else:
                self.dropped_results[v.value] += 1
        return None if verdicts and not self.commit() else tuple(verdicts)

    def _settle(self, worker_id: str, lease_id: int, result: Any, unreadable: str = "") -> Verdict:
        storage = self.study.storage
        tid = result.trial_id
        if not 0 <= tid < storage.n_trials():
            return Verdict.UNKNOWN
        if worker_id in self.unservable_workers:  # left out (other code, a run it cannot build): nothing of it
            return Verdict.INVALID
        if unreadable:  # a failed stand-in (protocol.submissions): it answers the trial's own seed
            result = replace(result, seed=int(storage.columns()["seed"][tid]))
        for kind in KINDS:  # a check's result quotes the check's lease and the row it checks
            key = check_key(kind, tid)
            if self.scheduler.is_current(key, lease_id, worker_id):
                return self.ladder.settle_check(key, worker_id, self._finite_or_failed(result))
            if self.scheduler.was_issued(key, lease_id, worker_id):
                return Verdict.STALE
        if storage.columns()["status"][tid] != TrialStatus.WAITING.stored:
            return Verdict.DUPLICATE
        if not self.scheduler.is_current(tid, lease_id, worker_id):
            if not self.scheduler.was_issued(tid, lease_id, worker_id):
                self.forged_results += 1
                log.warning("result for trial %d from %s quotes a lease it was never given: dropped", tid, worker_id)
            return Verdict.STALE
        refused = self.ladder.refuse_quarantined(tid, worker_id)
        if refused is not None:
            return refused
        if unreadable:
            log.warning("result for trial %d from %s cannot be read (%s): stored as failed", tid, worker_id,
                        unreadable)
        if result.seed != int(storage.columns()["seed"][tid]):
            log.warning("result for trial %d has seed %d, expected %d: dropped", tid, result.seed,
                        int(storage.columns()["seed"][tid]))
            return Verdict.INVALID
        if result.status == TrialStatus.FAILED and result.reason.startswith(RETRIED_REASONS):
            self.scheduler.retry(tid, result.reason)  # the trial, not the worker, may be at fault: again
            self._store_given_up()
            return Verdict.REQUEUED
        if result.worker_id != worker_id:
            result = replace(result, worker_id=worker_id)
        result = self._finite_or_failed(result)
        self.study.tell(result)
        self.scheduler.release(tid)
        self.scheduler.observe_trial(result.wall_time_s)
        self.ladder.after_trial(result)
        return Verdict.STORED

    def _finite_or_failed(self, result: TrialResult) -> TrialResult:
        """A complete result whose score is NaN or infinite is a failure (it could never rank)."""
        if not result.ok:
            return result
        parts = {"distance_m": result.distance_m, "ntrt_distance_cm": result.ntrt_distance_cm, "speed_cm_s":
                 result.speed_cm_s, "work_j": result.work_j, "objective": self.study.objective(result)}
        bad = [f"{k}={v!r}" for k, v in parts.items() if not math.isfinite(v)]
        if not bad:
            return result
        return replace(result, status=TrialStatus.FAILED, reason=f"non-finite score: {', '.join(bad)}")

    def _store_given_up(self) -> None:
        """Store trials the scheduler gave up on (they lost their worker too often) as failed (lock held)."""
        while self.scheduler.given_up:
            tid, reason = self.scheduler.given_up.pop(0)
            if tid < 0:  # a check: the best goes unchecked rather than holding up the run
                log.warning("%s check of trial %d %s: dropped", *split_key(tid), reason)
                self.ladder.checks.drop(tid)
                continue
            seed = int(self.study.storage.columns()["seed"][tid])
            log.warning("trial %d %s: stored as failed", tid, reason)
            self.study.tell(TrialResult.failed(reason, seed, trial_id=tid))

    def workers_released(self) -> bool:
        """Every worker that may still ask has heard that the run is done (so it can exit before we do):
        the live ones and those gone within the last lease without hearing it. A worker frozen, restarting
        or cut off as the run ends comes back to nobody once we are gone and waits out its
        --coordinator-timeout; one that is back while we wait hears "done" and exits at once."""
        with self.lock:
            now, lease_s = self.clock(), self.scheduler.lease_s
            return all(w.worker_id in self.told_done for w in self.scheduler.workers.values()
                       if w.alive or now - w.last_contact_s <= lease_s)

    def handle_config(self, config_hash: str) -> bytes:
        if config_hash != self.config_hash:
            return self._error("config request", MessageError(
                "unknown run config hash", received=config_hash, expected=self.config_hash))
        return self._config_payload

    def handle_problem(self, payload: bytes) -> bytes:
        """A worker cannot serve this run: the run stops with its reason (see `failure`)."""
        try:
            problem = decode_message(payload, WorkerProblem)
        except MessageError as exc:
            return self._error("worker problem", exc)
        with self.lock:
            if not self.scheduler.is_current(problem.trial_id, problem.lease_id, problem.worker_id):
                self.forged_results += 1  # only a worker holding this run's work may stop it
                return self._error("worker problem", MessageError(
                    "worker problem quotes no lease this worker holds", received=(problem.trial_id,
                                                                                  problem.lease_id),
                    expected="the trial id and lease id of a trial leased to that worker"))
            if self._served_by_others(problem.worker_id):
                self._leave_out(problem.worker_id, problem.reason)
            elif self.failure is None:
                self.failure = f"worker {problem.worker_id} cannot serve run {self.run_id}: {problem.reason}"
                log.error("%s", self.failure)
        return encode("ack", {})

    def _served_by_others(self, worker_id: str) -> bool:
        """Other workers have stored complete results of this run: one machine's problem (an old install, a
        missing engine) need not stop it (lock held)."""
        cols = self.study.storage.columns()
        return bool(((cols["status"] == b"complete") & (cols["worker_id"] != worker_id.encode())).any())

    def _leave_out(self, worker_id: str, reason: str) -> None:
        """The worker gets no more work of this run; what it holds goes to the others (lock held)."""
        self.unservable_workers[worker_id] = reason[:300]
        self.scheduler.take_back(worker_id)
        log.warning("worker %s is left out of run %s (%s); the run goes on without it", worker_id, self.run_id, reason)

    def claimed(self, other: str) -> None:
        """Another coordinator declared itself holder of this run (a copy of its file resumed on this network)."""
        with self.lock:
            if other in self.claims:
                return
            self.claims[other] = "refused: this coordinator holds the run" if other > self.holder else \
                "claims to have held it first (a partition that healed?)"
            log.error("another coordinator (run instance %s) claims run %s, held here by %s: %s; workers serve this "
                      "one", other, self.run_id, self.holder, self.claims[other])

    def run_info(self) -> bytes:
        return encode_message(RunInfo(self.run_id, self.config_hash, self.study.budget, self.study.done))

    # --- liveness and time ------------------------------------------------------------------------
    def worker_seen(self, worker_id: str) -> None:
        with self.lock:
            self.scheduler.contact(worker_id)

    def worker_lost(self, worker_id: str) -> list[int]:
        with self.lock:
            lost = self.scheduler.worker_lost(worker_id)
            self._store_given_up()
        if lost:
            log.info("worker %s lost; re-issuing trials %s", worker_id, lost[:10])
        return lost

    def tick(self) -> list[int]:
        """Expire overdue leases (called periodically by the transport)."""
        with self.lock:
            expired = self.scheduler.expire()
            self._store_given_up()
            return expired

    # --- status -----------------------------------------------------------------------------------
    def status(self) -> dict[str, Any]:
        """JSON-able live status: counts, rate, ETA, workers (the API reads it from the status file)."""
        from spinefarm.coordinator.status import live_status

        with self.lock:
            return live_status(self)

    def finish_rate(self) -> float:
        """Results stored per second over the last half minute (lock held)."""
        now = self.clock()
        while self._finish_times and self._finish_times[0] < now - _RATE_WINDOW_S:
            self._finish_times.popleft()
        window = min(_RATE_WINDOW_S, max(now - self.started_s, 1e-9))
        return len(self._finish_times) / window
