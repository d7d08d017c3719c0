"""A fit's generations computed by the project's workers over Zenoh (`spinefarm fit --workers N / --connect`).

The fitting process serves one run (worker.fit.task: its RunConfig holds the robot, the trial config and the
recordings) on the run keys every worker knows (protocol.keys): its info, its config by hash, work requests
and results. A generation's candidates become trials; each is leased to one worker at a time (one per
request: a candidate's loss is a long task, so a generation spreads over the workers), re-issued when its
lease runs out, and failed ones are issued again up to MAX_ATTEMPTS times. The first loss back for a candidate
is kept: every worker computes the same bits, as this process would.
"""

from __future__ import annotations

import json
import logging
import os
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import zenoh

from spinefarm.protocol import keys, limits
from spinefarm.protocol.credentials import Credentials
from spinefarm.protocol.envelope import decode_message, encode_message
from spinefarm.protocol.errors import ConfigError, SpinefarmError
from spinefarm.protocol.run import WorkerProblem
from spinefarm.protocol.submissions import ResultAck, ResultSubmission, SubmittedResult, Verdict
from spinefarm.protocol.work import RunInfo, TrialAssignment, WorkGrant, WorkRequest
from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.fit.loss import Prepared
from spinefarm.worker.fit.search import Bound
from spinefarm.worker.fit.task import LOSS_KEY, fit_run_config, simulated_s

log = logging.getLogger("spinefarm.fit")
MAX_ATTEMPTS = 3     # a candidate whose loss failed this often (crash, timeout, error) stops the fit
LEASE_S = 900.0      # a leased candidate not back by then is issued again (its worker vanished)
RETRY_AFTER_S = 0.2  # an idle worker asks again this soon: the next generation follows within a loss's time
DONE_WAIT_S = 5.0    # at the end, how long the fit waits for its workers to ask again and hear "done"


@dataclass(frozen=True)
class FitNetwork:
    """Where the fit's run is served: endpoints to listen on (workers connect here) and routers to join."""

    listen: Sequence[str] = ()
    connect: Sequence[str] = ()
    credentials: Credentials | None = None   # authenticate; when listening, refuse sessions without them

    def config(self) -> zenoh.Config:
        conf = zenoh.Config()
        if self.credentials is not None:
            for key, value in self.credentials.zenoh_settings(accept=bool(self.listen)).items():
                conf.insert_json5(key, value)
        conf.insert_json5("mode", json.dumps("router" if self.listen and not self.connect else "peer"))
        if self.listen:
            conf.insert_json5("listen/endpoints", json.dumps(list(self.listen)))
        if self.connect:
            conf.insert_json5("connect/endpoints", json.dumps(list(self.connect)))
        conf.insert_json5("scouting/multicast/enabled", "false")
        return conf


class RemoteLosses:
    """The fit's `losses` (search.minimise): a generation's candidates handed to workers, their losses back in
    order. on_wait: called while a generation waits; a text it returns stops the fit with that reason."""

    def __init__(self, morph: Morphology, cfg: TrialConfig, fitted: Sequence[Prepared], bounds: Sequence[Bound],
                 network: FitNetwork, on_wait: Callable[[], str | None] | None = None) -> None:
        config = fit_run_config("fit", morph, cfg, fitted, bounds)
        self.run_id = f"fit-{config.config_hash()}-{os.getpid()}"
        self.config = fit_run_config(self.run_id, morph, cfg, fitted, bounds)
        self._config_bytes = encode_message(self.config)
        if len(self._config_bytes) > limits.MAX_MESSAGE_BYTES:
            raise ConfigError("the fit's recordings are too large to send to workers", received=(
                f"{len(self._config_bytes)} bytes"), expected=f"at most {limits.MAX_MESSAGE_BYTES} bytes "
                "(fewer or shorter recordings, or --jobs N on this machine)")
        self.hash, self.sim_s, self.on_wait = self.config.config_hash(), simulated_s(fitted), on_wait
        self._lock = threading.Condition()
        self._values: dict[int, tuple[float, ...]] = {}
        self._losses: dict[int, float] = {}
        self._leases: dict[int, tuple[int, float]] = {}   # trial id -> (lease id, deadline)
        self._attempts: dict[int, int] = {}
        self._failure = ""
        self.by_worker: dict[str, int] = {}   # losses each worker computed (kept ones)
        self._asked: set[str] = set()   # workers that asked for work, and those told the run is done
        self._told: set[str] = set()
        self._next_trial = self._next_lease = 0
        self.done = False
        self.session = zenoh.open(network.config())
        s, prefix = self.session, keys.run_prefix(self.run_id)
        self._queryables = [s.declare_queryable(keys.run_info(self.run_id), self._answer(self._info)),
                            s.declare_queryable(f"{prefix}/config/*", self._answer(self._on_config)),
                            s.declare_queryable(keys.work(self.run_id), self._answer(self._work)),
                            s.declare_queryable(keys.results(self.run_id), self._answer(self._results)),
                            s.declare_queryable(keys.problem(self.run_id), self._answer(self._problem))]

    def __call__(self, candidates: list[dict[str, float]]) -> list[float]:
        with self._lock:
            ids = list(range(self._next_trial, self._next_trial + len(candidates)))
            self._next_trial += len(candidates)
            for i, c in zip(ids, candidates, strict=True):
                self._values[i] = tuple(c[p["name"]] for p in self.config.param_space)
            while not all(i in self._losses for i in ids):
                if self._failure:
                    raise SpinefarmError(self._failure)
                self._lock.wait(0.5)
                if self.on_wait is not None and (why := self.on_wait()):
                    raise SpinefarmError(why)
            for i in ids:  # a late result for one of them is then unknown, never issued again
                del self._values[i]
                self._leases.pop(i, None)
            return [self._losses.pop(i) for i in ids]

    def close(self) -> None:
        """Every worker that served the run is told it is done (a roaming worker stays with a run until told; up
        to DONE_WAIT_S), then the run's keys go."""
        with self._lock:
            self.done = True
            end = time.monotonic() + DONE_WAIT_S
            while not self._asked <= self._told and time.monotonic() < end:
                self._lock.wait(RETRY_AFTER_S)
        for q in self._queryables:
            q.undeclare()
        self.session.close()

    # --- queries (zenoh threads) -----------------------------------------------------------------
    def _answer(self, handler: Callable[[bytes, str], bytes]) -> Callable[[zenoh.Query], None]:
        def on_query(query: zenoh.Query) -> None:
            with query:
                try:
                    payload = query.payload.to_bytes() if query.payload is not None else b""
                    query.reply(query.key_expr, handler(payload, str(query.key_expr)))
                except Exception:  # a transport callback must not die: log and keep serving
                    log.exception("fit query on %s failed", query.key_expr)
        return on_query

    def _info(self, _: bytes, __: str) -> bytes:
        return encode_message(RunInfo(self.run_id, self.hash, self._next_trial, self.done))

    def _on_config(self, _: bytes, key: str) -> bytes:
        if key.rsplit("/", 1)[-1] != self.hash:
            raise ConfigError("no such config", received=key, expected=self.hash)
        return self._config_bytes

    def _work(self, payload: bytes, _: str) -> bytes:
        req = decode_message(payload, WorkRequest)
        with self._lock:
            verdicts = self._take(req.results)
            now, grant = time.monotonic(), []
            todo = [i for i in sorted(self._values) if i not in self._losses
                    and (i not in self._leases or self._leases[i][1] < now)]
            for i in todo[:1]:
                self._next_lease += 1
                self._leases[i] = (self._next_lease, now + LEASE_S)
                grant.append(TrialAssignment(i, self._next_lease, self._values[i], 0, LEASE_S, self.sim_s))
            self._asked.add(req.worker_id)
            if self.done and not grant:
                self._told.add(req.worker_id)
                self._lock.notify_all()
        return encode_message(WorkGrant(self.run_id, self.hash, tuple(grant), 0.0 if grant else RETRY_AFTER_S,
                                        self.done and not grant, verdicts, self.run_id))

    def _results(self, payload: bytes, _: str) -> bytes:
        sub = decode_message(payload, ResultSubmission)
        with self._lock:
            return encode_message(ResultAck(self._take(sub.items), self.run_id))

    def _problem(self, payload: bytes, _: str) -> bytes:
        problem = decode_message(payload, WorkerProblem)
        with self._lock:
            self._failure = f"worker {problem.worker_id} cannot compute the fit's losses: {problem.reason}"
            self._lock.notify_all()
        return b""

    def _take(self, items: Sequence[SubmittedResult]) -> tuple[tuple[int, Verdict], ...]:
        """Results in (under the lock): a candidate's first loss is kept; a failure is issued again."""
        out = []
        for item in items:
            i, r = item.result.trial_id, item.result
            if i not in self._values:
                out.append((i, Verdict.UNKNOWN))
            elif i in self._losses or self._leases.get(i, (None,))[0] != item.lease_id:
                out.append((i, Verdict.DUPLICATE if i in self._losses else Verdict.STALE))
            elif r.ok and isinstance(r.extras.get(LOSS_KEY), float):
                self._losses[i] = r.extras[LOSS_KEY]
                self.by_worker[r.worker_id] = self.by_worker.get(r.worker_id, 0) + 1
                out.append((i, Verdict.STORED))
            else:
                self._attempts[i] = self._attempts.get(i, 0) + 1
                self._leases.pop(i, None)
                if self._attempts[i] >= MAX_ATTEMPTS:
                    self._failure = f"a candidate's loss failed {MAX_ATTEMPTS} times, last: {r.reason}"
                out.append((i, Verdict.REQUEUED))
        self._lock.notify_all()
        return tuple(out)
