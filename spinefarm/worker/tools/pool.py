"""The process pool of a long local command (calibrate, accuracy): its processes end with the command.

A terminal's Ctrl-C reaches the whole foreground group: the pool's processes ignore SIGINT and the command,
which gets it too, terminates them (a process running a trial would otherwise take the interrupt as that
trial's error and go on with the next). A script's SIGINT or SIGTERM reaches the command alone: it
terminates the pool on its way out; a command killed before it can (SIGTERM's default action, SIGKILL) has
the kernel send SIGKILL to each of its pool processes. Completion is reported per job to `progress(done,
total)` for the command's progress line.
"""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing as mp
import signal
from collections.abc import Callable, Iterator
from multiprocessing.pool import Pool
from typing import Any

PR_SET_PDEATHSIG = 1

Progress = Callable[[int, int], None]


def _start_child() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides when the pool stops
    with contextlib.suppress(OSError, AttributeError):  # not Linux: the parent's terminate() alone
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)


@contextlib.contextmanager
def process_pool(processes: int) -> Iterator[Pool]:
    """A forked pool, terminated (not waited for) when the block ends with an exception, KeyboardInterrupt
    and SystemExit included."""
    pool = mp.get_context("fork").Pool(processes, initializer=_start_child)
    try:
        yield pool
    except BaseException:
        pool.terminate()
        raise
    else:
        pool.close()
    finally:
        pool.join()


def run_jobs(fn: Callable[[Any], Any], jobs: list, processes: int, progress: Progress | None = None) -> list:
    """[fn(job) for job in jobs], in `processes` processes when more than one, in order."""
    out: list = []
    total = len(jobs)
    if processes <= 1 or total <= 1:
        for job in jobs:
            out.append(fn(job))
            if progress:
                progress(len(out), total)
        return out
    with process_pool(min(processes, total)) as pool:
        for result in pool.imap(fn, jobs):
            out.append(result)
            if progress:
                progress(len(out), total)
    return out
