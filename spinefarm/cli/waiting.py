"""Progress with an ETA for a command's long wait (a calibration, an accuracy sweep, a structure check, a fit):
one line redrawn in place on a terminal, a plain line every few seconds otherwise (a log, a pipe, a script).

A command makes one `Waiting(what, unit)` and passes it wherever `progress(done, total)` is taken (worker.tools.pool's
Progress). A wait shorter than SHOW_AFTER_S shows nothing on a terminal; a log always gets its first and last line.
A parent process that runs the command in a child and forwards its standard error sets PROGRESS_ENV: "tty"
(the child draws for the parent's terminal), "lines" (plain lines) or "off" (the parent's --quiet).
"""

from __future__ import annotations

import os
import sys
import time
from typing import TextIO

LOG_EVERY_S = 5.0  # a plain line at most this often
DRAW_EVERY_S = 0.2  # a terminal's line at most this often
SHOW_AFTER_S = 2.0  # a terminal's line appears only for a wait this long
PROGRESS_ENV = "SPINEFARM_PROGRESS"


def duration_text(seconds: float) -> str:
    """`42 s`, `3 min 05 s`, `1 h 02 min`."""
    s = max(0, round(seconds))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"


def progress_text(what: str, unit: str, done: int, total: int, elapsed_s: float) -> str:
    """`calibration: 12/98 trials (12 %), 34 s elapsed, about 4 min 04 s left`."""
    pct = 100 * done // total if total else 100
    if done >= total:
        left = "done"
    elif done == 0:
        left = "estimating the time left"
    else:
        left = f"about {duration_text(elapsed_s / done * (total - done))} left"
    return f"{what}: {done}/{total} {unit} ({pct} %), {duration_text(elapsed_s)} elapsed, {left}"


class Waiting:
    """Callable as progress(done, total); `close()` ends the line."""

    def __init__(self, what: str, unit: str, *, stream: TextIO | None = None, tty: bool | None = None,
                 quiet: bool = False) -> None:
        mode = os.environ.get(PROGRESS_ENV)
        self.what, self.unit, self.quiet = what, unit, quiet or mode == "off"
        self.stream = stream or sys.stderr
        if tty is None:
            tty = mode == "tty" or (mode != "lines" and self.stream.isatty())
        self.tty = tty
        self.start = time.monotonic()
        self._shown = 0.0 if tty else -LOG_EVERY_S  # a log gets its first line at once
        self._drawn = False
        self._last: tuple[int, int] | None = None
        self._printed: tuple[int, int] | None = None

    def __call__(self, done: int, total: int) -> None:
        if self.quiet:
            return
        self._last = (done, total)
        now = time.monotonic()
        if self.tty:
            if now - self.start >= SHOW_AFTER_S and (now - self._shown >= DRAW_EVERY_S or done >= total):
                self._draw(done, total, now)
        elif now - self._shown >= LOG_EVERY_S:
            self._line(done, total, now)

    def _draw(self, done: int, total: int, now: float) -> None:
        text = progress_text(self.what, self.unit, done, total, now - self.start)
        self.stream.write(f"\r\x1b[K{text}")
        self.stream.flush()
        self._shown, self._drawn = now, True

    def _line(self, done: int, total: int, now: float) -> None:
        print(progress_text(self.what, self.unit, done, total, now - self.start), file=self.stream, flush=True)
        self._shown, self._printed = now, (done, total)

    def close(self) -> None:
        """A terminal's line stays as last drawn (then a new line); a log gets the last state once more."""
        if self.quiet or self._last is None:
            return
        now = time.monotonic()
        if self.tty:
            if self._drawn:
                self._draw(*self._last, now)
                self.stream.write("\n")
                self.stream.flush()
        elif self._printed != self._last:
            self._line(*self._last, now)

    def __enter__(self) -> Waiting:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
