"""A stop signal that lands while the main thread holds its stop event's lock still stops the command.

Event.set() called from a signal handler waits for ever for that lock (the handler runs in the thread that
holds it); cli.stop_signals sets the event from another thread.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

SCRIPT = textwrap.dedent("""
    import os, signal, threading, time
    from spinefarm.cli.stop_signals import stop_on_signals

    stop = threading.Event()
    seen = stop_on_signals(stop)
    with stop._cond:  # where Event.wait is, several times a second, in the commands' main loops
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.01)  # the handler runs at a bytecode in here
    print("stopped" if stop.wait(10) else "not stopped", seen == [signal.SIGTERM], flush=True)
""")


def test_a_signal_while_the_main_thread_holds_the_stop_events_lock_still_stops_it() -> None:
    out = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=30)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["stopped", "True"]
