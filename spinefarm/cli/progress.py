"""The search's progress line: a tqdm bar on a terminal, a plain line every few seconds in a log.

Everything else the search prints while the bar is up goes through `write` (and logging through
tqdm's redirect), so the bar is redrawn below it instead of being broken; local workers and the
re-simulation process write to files or nowhere, never to this terminal.
"""

from __future__ import annotations

import os
import shutil
import sys
import time
from contextlib import AbstractContextManager, nullcontext
from typing import TextIO

LOG_EVERY_S = 5.0


class ProgressLine:
    def __init__(self, total: int, *, quiet: bool = False, stream: TextIO | None = None) -> None:
        self.stream = stream or sys.stderr
        self.quiet = quiet
        self.tty = self.stream.isatty()
        self._last = 0.0
        self._bar = None
        if self.tty and not quiet:
            from tqdm import tqdm

            # A terminal that reports no size (0 x 0, e.g. a bare pty) would get no bar at all: assume one.
            try:
                size = os.get_terminal_size(self.stream.fileno())
                sized = size.columns > 0 and size.lines > 0
            except (OSError, ValueError):
                sized = False
            fallback = shutil.get_terminal_size((100, 24))
            self._bar = tqdm(total=total, unit="set", file=self.stream, leave=True, dynamic_ncols=sized,
                             ncols=None if sized else fallback.columns, nrows=None if sized else 24,
                             bar_format="{l_bar}{bar}| {n}/{total} parameter sets [{elapsed}<{remaining}{postfix}]")

    def logging_redirect(self) -> AbstractContextManager:
        """Route log records above the bar while it is shown."""
        if self._bar is None:
            return nullcontext()
        from tqdm.contrib.logging import logging_redirect_tqdm

        return logging_redirect_tqdm()

    def update(self, done: int, total: int, text: str, plain: str) -> None:
        """`text`: what follows the bar; `plain`: the whole line for a log (printed every few seconds)."""
        if self.quiet:
            return
        if self._bar is not None:
            self._bar.total = total
            self._bar.n = done
            self._bar.set_postfix_str(text, refresh=False)
            self._bar.refresh()
            return
        now = time.monotonic()
        if now - self._last >= LOG_EVERY_S:
            print(plain, file=self.stream, flush=True)
            self._last = now

    def write(self, message: str) -> None:
        if self._bar is not None:
            self._bar.write(message, file=self.stream)
        else:
            print(message, file=self.stream, flush=True)

    def close(self, plain: str) -> None:
        """Final state: the bar stays on screen; a log gets the last plain line."""
        if self._bar is not None:
            self._bar.close()
        elif not self.quiet:
            print(plain, file=self.stream, flush=True)
