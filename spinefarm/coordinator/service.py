"""The coordinator's Zenoh edge: queryables for run info, work, results and config; worker liveliness.

The only coordinator module that imports zenoh. By default the coordinator is itself a Zenoh router
listening on loopback, so a local run needs no separate daemon; `connect` joins an existing router.
A background thread expires leases, flushes storage at a bounded interval and writes the status file.

One writer per run: the coordinator declares a liveliness token naming its session under its run; one that
finds an earlier holder of its run on the network (a copy of the run's file resumed beside the original)
refuses to start, and the original logs the claim and shows it in its status. Grants name the holder, and
workers stay with it. Another thread asks each new worker's identity queryable and keeps the Zenoh session
id of the reply (Zenoh sets it, the worker does not choose it): audits go to another session.
"""

from __future__ import annotations

import json
import logging
import os
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import zenoh

from spinefarm.coordinator.core import CoordinatorCore
from spinefarm.protocol import keys
from spinefarm.protocol.code_digest import code_digest
from spinefarm.protocol.credentials import Credentials, is_loopback
from spinefarm.protocol.envelope import decode_message
from spinefarm.protocol.errors import ConfigError
from spinefarm.protocol.work import WorkRequest
from spinefarm.storage.base import BaseStorage
from spinefarm.storage.status import write_final_status, write_status

log = logging.getLogger("spinefarm.coordinator")
DEFAULT_LISTEN = ("tcp/127.0.0.1:7447",)
PROBE_TIMEOUT_S = 5.0   # an identity queryable answers in milliseconds, on a loaded machine in seconds
PROBE_AGAIN_S = 5.0


def zenoh_config(mode: str, listen: Sequence[str] = (), connect: Sequence[str] = (),
                 config_file: str | Path | None = None, credentials: Credentials | None = None) -> zenoh.Config:
    """A Zenoh config: a JSON5 file passed through (TLS, access control), then our explicit settings.

    Multicast scouting is off: peers meet only through explicit endpoints, never a stray network.
    credentials: authenticate with them, and (when listening) refuse every session without them.
    """
    try:
        conf = zenoh.Config.from_file(str(config_file)) if config_file else zenoh.Config()
    except Exception as exc:  # zenoh raises its own error type for unreadable files
        raise ConfigError(f"cannot read Zenoh config {config_file}: {exc}", expected="a JSON5 file") from exc
    conf.insert_json5("mode", json.dumps(mode))
    if listen:
        conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    if connect:
        conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    conf.insert_json5("scouting/multicast/enabled", "false")
    if credentials is not None:
        for key, value in credentials.zenoh_settings(accept=bool(listen)).items():
            conf.insert_json5(key, value)
    elif any(not is_loopback(e) for e in listen):
        log.warning("listening on %s without --credentials: anyone who reaches it can take and return work",
                    ", ".join(e for e in listen if not is_loopback(e)))
    return conf


def _timed_work(handler: Callable[[bytes], bytes | None]) -> Callable[[bytes], bytes | None]:
    """With SPINEFARM_GRANT_LOG set (bench/scale.py): one line per work request, its arrival (wall clock),
    the time the core took over it (lock wait included) and the worker, so a bench can tell the coordinator's
    part of a grant's latency from the transport's and its own clients'."""
    path = os.environ.get("SPINEFARM_GRANT_LOG")
    if not path:
        return handler
    out = open(path, "a", buffering=1)  # noqa: SIM115 (lives with the coordinator)

    def timed(payload: bytes) -> bytes | None:
        arrived, t0 = time.time(), time.perf_counter()
        answer = handler(payload)
        took_ms = 1000 * (time.perf_counter() - t0)
        try:
            worker = decode_message(payload, WorkRequest).worker_id
        except Exception:
            worker = "?"
        out.write(f"{arrived:.6f} {took_ms:.3f} {worker}\n")
        return answer
    return timed


def _stored_instance(storage: BaseStorage) -> str:
    try:
        return storage.run_meta().instance
    except Exception:  # a storage without a run yet (a core driven in-process): no stored instance
        return ""


def _payload(query: zenoh.Query) -> bytes:
    return query.payload.to_bytes() if query.payload is not None else b""


class CoordinatorService:
    def __init__(self, core: CoordinatorCore, storage: BaseStorage, *, listen: Sequence[str] = DEFAULT_LISTEN,
                 connect: Sequence[str] = (), zenoh_config_file: str | Path | None = None,
                 status_file_for: str | Path | None = None, flush_interval_s: float = 1.0,
                 tick_s: float = 0.1, credentials: Credentials | None = None) -> None:
        self.core = core
        self.storage = storage
        mode = "router" if listen and not connect else "peer"
        self._conf = zenoh_config(mode, listen, connect, zenoh_config_file, credentials)
        self._status_for = status_file_for
        self.flush_interval_s = flush_interval_s
        self.tick_s = tick_s
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._session: zenoh.Session | None = None
        self._entities: list = []
        self.close_warnings: list[str] = []  # what close() could not do although every result is stored

    def start(self) -> CoordinatorService:
        try:
            self._session = s = zenoh.open(self._conf)
        except Exception as exc:
            raise ConfigError(f"cannot open the Zenoh session: {exc}",
                              expected="free listen endpoints / a reachable router") from exc
        run = self.core.run_id
        # the run instance the file recorded when it was opened (storage.schema.RunMeta.opened): grants name it,
        # results carry it back, and results leased by another instance are refused. A core served again (its
        # leases still in memory) stays the same instance.
        self.core.holder = self.core.holder or _stored_instance(self.storage) or \
            f"{time.time_ns() // 1_000_000}-{s.zid()}"
        self.core.code_digest = self.core.code_digest or code_digest()
        self.core.peers.verify_identity = True
        self._hold(s, run)
        # work last: a worker granted trials before the config queryable is declared finds no config to run them
        self._entities += [
            s.declare_queryable(f"{keys.run_prefix(run)}/config/*", self._on_config),
            s.declare_queryable(keys.results(run), self._guard(self.core.handle_results)),
            s.declare_queryable(keys.problem(run), self._guard(self.core.handle_problem)),
            s.declare_queryable(keys.run_info(run), self._on_info),
            s.declare_queryable(keys.work(run), self._guard(_timed_work(self.core.handle_work))),
            s.liveliness().declare_subscriber(keys.all_worker_tokens(), self._on_liveliness, history=True),
        ]
        self._thread = threading.Thread(target=self._housekeeping, name="coordinator-housekeeping",
                                        daemon=True)
        self._thread.start()
        threading.Thread(target=self._probe_identities, name="coordinator-identities", daemon=True).start()
        return self

    def _hold(self, s: zenoh.Session, run: str) -> None:
        """Declare this coordinator the run's holder; refuse (ConfigError) if another held it first."""
        holder = self.core.holder
        self._entities = [s.liveliness().declare_token(keys.holder_token(run, holder))]
        others = set()
        for reply in s.liveliness().get(keys.all_holder_tokens(run), timeout=PROBE_TIMEOUT_S):
            if reply.ok is not None:
                others.add(keys.holder_of_token(str(reply.ok.key_expr)))
        earlier = sorted(o for o in others if o < holder)
        if earlier:
            self._entities[0].undeclare()
            self._entities = []
            s.close()
            self._session = None
            raise ConfigError(f"run {run} is already held by another coordinator on this network (run instance "
                              f"{earlier[0]}): a copy of its file cannot serve it while that one runs",
                              expected="the original coordinator stopped, or the copy resumed on another network")
        self._entities.append(s.liveliness().declare_subscriber(keys.all_holder_tokens(run), self._on_holder))

    def _on_holder(self, sample: zenoh.Sample) -> None:
        try:
            other = keys.holder_of_token(str(sample.key_expr))
            if sample.kind == zenoh.SampleKind.PUT and other != self.core.holder:
                self.core.claimed(other)
        except Exception:
            log.exception("holder event failed")

    def _probe_identities(self) -> None:
        """Ask each new worker's identity queryable; the sessions that answer are its identity."""
        asked: dict[str, float] = {}
        while not self._stop.wait(0.1):
            with self.core.lock:
                todo = [w for w in self.core.peers.unidentified() if asked.get(w, 0.0) <= time.monotonic()]
            for wid in todo:
                session = self._session
                if session is None or self._stop.is_set():
                    return
                try:
                    sessions = {str(r.replier_id.zid) for r in session.get(
                        keys.worker_identity(wid), timeout=PROBE_TIMEOUT_S, consolidation=zenoh.ConsolidationMode.NONE)
                        if r.ok is not None and r.replier_id is not None}
                    self.core.identified(wid, sessions)
                except Exception:
                    log.exception("identity probe of worker %s failed", wid)
                asked[wid] = time.monotonic() + PROBE_AGAIN_S

    # --- callbacks (zenoh threads) ----------------------------------------------------------------
    def _guard(self, handler: Callable[[bytes], bytes | None]) -> Callable[[zenoh.Query], None]:
        def on_query(query: zenoh.Query) -> None:
            # `with` finalises the query at once; a reference kept elsewhere (a logged traceback)
            # would otherwise hold the requester until its timeout.
            with query:
                try:
                    answer = handler(_payload(query))
                    if answer is not None:  # None: the core stopped taking work (see CoordinatorCore.failure)
                        query.reply(query.key_expr, answer)
                except Exception:  # a transport callback must never die: log and keep serving
                    log.exception("query on %s failed", query.key_expr)
        return on_query

    def _on_info(self, query: zenoh.Query) -> None:
        with query:
            try:
                query.reply(keys.run_info(self.core.run_id), self.core.run_info())
            except Exception:
                log.exception("run info query failed")

    def _on_config(self, query: zenoh.Query) -> None:
        with query:
            try:
                config_hash = str(query.key_expr).rsplit("/", 1)[-1]
                query.reply(query.key_expr, self.core.handle_config(config_hash))
            except Exception:
                log.exception("config query failed")

    def _on_liveliness(self, sample: zenoh.Sample) -> None:
        try:
            worker_id = keys.worker_id_of_token(str(sample.key_expr))
            if worker_id is None:
                return
            if sample.kind == zenoh.SampleKind.DELETE:
                self.core.worker_lost(worker_id)
            else:
                self.core.worker_seen(worker_id)
        except Exception:
            log.exception("liveliness event failed")

    # --- housekeeping -----------------------------------------------------------------------------
    def _housekeeping(self) -> None:
        last_flush = time.monotonic()
        while not self._stop.wait(self.tick_s):
            try:
                self.core.tick()
                if time.monotonic() - last_flush >= self.flush_interval_s:
                    self.flush()
                    last_flush = time.monotonic()
            except Exception:
                log.exception("housekeeping failed")

    def flush(self) -> None:
        with self.core.lock:
            self.core.commit()
            status = self.core.status()
        if self._status_for is not None:
            try:
                write_status(self._status_for, status)
            except OSError as exc:  # a full disk must not stop housekeeping (leases still expire)
                log.warning("cannot write the status file: %s", exc)

    def wait_done(self, timeout_s: float | None = None, poll_s: float = 0.05) -> bool:
        end = None if timeout_s is None else time.monotonic() + timeout_s
        while not self.core.done and self.core.failure is None:
            if end is not None and time.monotonic() >= end:
                return False
            time.sleep(poll_s)
        return True

    def close(self) -> None:
        """Stop serving, store everything, release the file and the session."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        for e in self._entities:
            try:
                e.undeclare()
            except Exception:
                log.debug("undeclare failed", exc_info=True)
        self._entities = []
        try:
            self.core.commit()
            with self.core.lock:
                status = self.core.status()
            if self._status_for is not None:
                if self.core.write_failure is None and status["state"] != "done":
                    status["state"] = "stopped"
                # a full disk here loses no result (each was synced before its ack): said, never raised
                self.close_warnings = [w for w in [write_final_status(self._status_for, status)] if w]
        finally:
            with self.core.lock:
                self.storage.close()
            if getattr(self.storage, "close_warning", None):
                self.close_warnings.append(self.storage.close_warning)
            if self._session is not None:
                self._session.close()
                self._session = None
