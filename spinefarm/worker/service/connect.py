"""Reaching the coordinator: open a session with back-off until stopped, and say once why it cannot.

The session itself comes from a function the service passes in (a Zenoh open), so this module imports
no transport: only the policy of retrying and of telling an unreachable endpoint from one that refuses.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any, Generic, TypeVar

from spinefarm.worker.service.pacing import EXIT_REFUSED, Backoff, listening_endpoints

log = logging.getLogger("spinefarm.worker")
# A worker still without its coordinator after this long says so (then keeps trying).
UNREACHABLE_WARN_S = 3.0
Session = TypeVar("Session")


def timed_out(reply: Any) -> bool:
    """A Zenoh error reply that only says the query's time ran out (a busy coordinator): no refusal, so what the
    query carried is sent again, not dropped."""
    err = getattr(reply, "err", None)
    return err is not None and err.payload.to_string() == "Timeout"


class Connector(Generic[Session]):
    """open_session: one attempt, raising `retry_on` while the endpoints cannot be reached; endpoints: what
    the worker connects to (named in the warnings). With exit_when_done a refusal that lasts
    coordinator_timeout_s gives up with exit_code EXIT_REFUSED."""

    def __init__(self, open_session: Callable[[], Session], retry_on: type[BaseException],
                 endpoints: Sequence[str], stop: threading.Event, *, exit_when_done: bool,
                 coordinator_timeout_s: float) -> None:
        self._open_session = open_session
        self._retry_on = retry_on
        self._endpoints = tuple(endpoints)
        self._stop = stop
        self._exit_when_done = exit_when_done
        self._coordinator_timeout_s = coordinator_timeout_s
        self._said_unreachable = False
        self.exit_code = 0

    def open(self) -> Session | None:
        """A client session opens only once its router is reachable: retry with back-off until stopped."""
        backoff = Backoff(0.1, 2.0)
        since, told, refused_since = time.monotonic(), "", time.monotonic()
        where = ", ".join(self._endpoints) or "the configured endpoints"
        while not self._stop.is_set():
            try:
                # an attempt that hangs past the warning time is said to hang, not left silent
                return self._open_once(since + UNREACHABLE_WARN_S, where if not told else None)
            except self._retry_on as exc:
                log.info("coordinator not reachable yet (%s); retrying", exc)
                told = "unreachable" if self._said_unreachable and not told else told
                if time.monotonic() - since >= UNREACHABLE_WARN_S:
                    listening = listening_endpoints(self._endpoints)
                    state = "refused" if listening else "unreachable"
                    if state == "refused" and told != state:
                        refused_since = time.monotonic()
                        log.error("refused by %s: it accepts connections but not this worker's Zenoh session "
                                  "(missing or wrong --credentials, or TLS settings that do not match)",
                                  ", ".join(listening))
                    elif state != told:
                        log.warning("cannot reach a coordinator at %s; still trying (Ctrl-C to stop)", where)
                    told = state
                    # a proxy in front of a restarting coordinator refuses for a few seconds too: give up only
                    # after --coordinator-timeout of refusals
                    if (state == "refused" and self._exit_when_done
                            and time.monotonic() - refused_since >= self._coordinator_timeout_s):
                        log.error("giving up (--exit-when-done): refused for %.0f s", time.monotonic() - refused_since)
                        self.exit_code = EXIT_REFUSED
                        return None
                self._stop.wait(backoff.next())
        return None

    def _open_once(self, warn_at: float, where: str | None) -> Session | None:
        """One attempt, in a thread so that Ctrl-C is answered at once even while Zenoh waits on an endpoint
        that accepts TCP but never answers its handshake; None when stopped first (the attempt is abandoned).
        Still connecting at monotonic time `warn_at`: say that `where` cannot be reached (once)."""
        outcome: list = []
        done = threading.Event()

        def attempt() -> None:
            try:
                outcome.append(self._open_session())
            except BaseException as exc:  # handed to the caller's thread
                outcome.append(exc)
            done.set()

        threading.Thread(target=attempt, name="zenoh-open", daemon=True).start()
        while not done.wait(0.1):
            if self._stop.is_set():
                return None
            if where is not None and time.monotonic() >= warn_at:
                listening = listening_endpoints(self._endpoints)
                if listening:
                    log.warning("%s accepts connections but no Zenoh session has answered yet (a coordinator "
                                "that is not one, or TLS settings that do not match); still trying (Ctrl-C to stop)",
                                ", ".join(listening))
                else:
                    log.warning("cannot reach a coordinator at %s; still trying (Ctrl-C to stop)", where)
                    self._said_unreachable = True
                where = None
        if isinstance(outcome[0], BaseException):
            raise outcome[0]
        return outcome[0]
