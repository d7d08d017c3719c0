"""A helper process that stops with the process that started it, even one killed with SIGKILL.

On Linux the child asks the kernel for a signal when its parent dies (PR_SET_PDEATHSIG): the local workers
and the engine calibration of `spinefarm search` get SIGTERM (they may clean up), a worker's trial process
gets SIGKILL (a hung trial sits in C and would never run a handler). Elsewhere the starting command's own
clean-up stops them. The worker may not import the CLI, so the one copy lives here, where both may.
"""

from __future__ import annotations

import contextlib
import ctypes
import signal
import sys
from collections.abc import Callable

PR_SET_PDEATHSIG = 1  # linux/prctl.h


def die_with_parent(signum: int = signal.SIGTERM) -> None:
    """Ask the kernel to send this process `signum` when its parent dies (call it in the child)."""
    with contextlib.suppress(OSError, AttributeError):  # no prctl outside Linux
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signum)


# subprocess's preexec_fn (runs in the child between fork and exec) for a helper started by a command: SIGTERM
# when the command dies; None where the kernel has no such request, so no preexec_fn runs there
HELPER_PREEXEC: Callable[[], None] | None = die_with_parent if sys.platform.startswith("linux") else None
