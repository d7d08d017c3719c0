"""File-system helpers of the run-file writer: OS error texts, trimming, directory fsync, read-only
files, and silencing HDF5's repeats of a write error already reported."""

from __future__ import annotations

import os
import re
import stat
import sys
from pathlib import Path
from typing import Any

from spinefarm.protocol.errors import StorageError
from spinefarm.storage.probe import stored_eof


def _reason(exc: BaseException) -> str:
    """The OS error behind an HDF5 failure ('No space left on device'), else the exception's first line."""
    m = re.search(r"error message = '([^']+)'", str(exc))
    if m:
        return m.group(1)
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    return str(exc).splitlines()[0][:200] if str(exc) else type(exc).__name__


def _trim(path: Path) -> None:
    """Cut a closed file's unused reserve (beyond the end its superblock states)."""
    with open(path, "r+b") as fh:
        end = stored_eof(fh.read(2048 + 48))
        if end is not None and os.fstat(fh.fileno()).st_size > end:
            fh.truncate(end)
            os.fsync(fh.fileno())


def _fsync_dir(path: Path) -> None:
    """Make a created or replaced directory entry durable (the file's own fsync does not cover it)."""
    fd = os.open(path.parent, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _quiet_failed_deallocs() -> None:
    """After a failed write HDF5 retries the write whenever h5py frees an object of the file, and h5py
    prints each failure as a 'Can't decrement id ref count' traceback (through sys.excepthook, then as
    'Exception ignored'). The error is reported once (write_error); these repeats of it are dropped,
    every other exception still printed."""
    if getattr(sys.unraisablehook, "__name__", "") == "quiet_h5py_deallocs":
        return
    unraisable_hook, except_hook = sys.unraisablehook, sys.excepthook

    def _repeat(exc: BaseException | None) -> bool:
        return isinstance(exc, RuntimeError) and "decrement id ref count" in str(exc)

    def quiet_h5py_deallocs(unraisable: Any) -> None:
        if not _repeat(unraisable.exc_value):
            unraisable_hook(unraisable)

    def quiet_h5py_tracebacks(kind: type[BaseException], value: BaseException, tb: Any) -> None:
        if not _repeat(value):
            except_hook(kind, value, tb)

    sys.unraisablehook, sys.excepthook = quiet_h5py_deallocs, quiet_h5py_tracebacks


def _refuse_read_only(path: Path) -> None:
    """A run file without write permission stays as it is (root could replace it regardless)."""
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        return
    if not mode & (stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH):
        raise StorageError("run file is read-only", received=str(path),
                           expected="a writable run file (chmod u+w to continue it, or copy it)")
