"""Stop a long-running command on SIGINT / SIGTERM without a handler that can hang it.

A Python signal handler runs in the main thread between two bytecodes, possibly while that thread holds
the lock inside a threading.Event (in Event.wait, several times a second): a handler calling Event.set()
then waits for that lock for ever, and so does every later signal. The handler here only appends to a
list; a daemon thread sees the list grow and sets the event.

A signal sent to the process may be delivered to any thread that does not block it, Zenoh's runtime threads
among them; Python then runs the handler only when the main thread next runs bytecode. A main thread blocked
without a timeout (Event.wait()) would never run it: wait with `wait_for_stop`, which wakes every POLL_S.
"""

from __future__ import annotations

import signal
import threading
import time

POLL_S = 0.05  # how soon the event follows the signal


def stop_on_signals(stop: threading.Event, signals: tuple[int, ...] = (signal.SIGINT, signal.SIGTERM)) -> list[int]:
    """Set `stop` when one of `signals` arrives (call from the main thread). Returns the list the signals'
    numbers are appended to, in order of arrival."""
    seen: list[int] = []

    def handler(signum: int, _frame: object) -> None:
        seen.append(signum)  # a list append takes no lock that the interrupted code may hold

    for sig in signals:
        signal.signal(sig, handler)

    def watch() -> None:
        while not seen:
            time.sleep(POLL_S)
        stop.set()

    threading.Thread(target=watch, name="stop-signals", daemon=True).start()
    return seen


def wait_for_stop(stop: threading.Event) -> None:
    """Block the main thread until `stop` is set, waking every POLL_S so that a signal delivered to another
    thread is handled (see the module's docstring)."""
    while not stop.wait(POLL_S):
        pass

