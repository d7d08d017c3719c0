"""One writer per run file: an exclusive lock on the sidecar RUN.h5.lock, held while a coordinator writes.

flock on a sidecar (never on the HDF5 file itself, which HDF5 opens and closes on its own terms) is
seen by every process on the machine, also across `--overwrite` and `--resume`, which take it before
touching the run file. The kernel releases it when the holder dies, so a SIGKILLed coordinator never
leaves a stale lock. The sidecar stays in place: deleting a lock file races with its next taker.
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

from spinefarm.protocol.errors import StorageError


def lock_path(run_path: str | Path) -> Path:
    p = Path(run_path)
    return p.with_name(p.name + ".lock")


class RunLock:
    """Held from `acquire()` until `release()` (or the process ends)."""

    def __init__(self, run_path: str | Path) -> None:
        self.run_path = Path(run_path)
        self.path = lock_path(run_path)
        self._fd: int | None = None

    def acquire(self) -> RunLock:
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        except OSError as exc:
            raise StorageError(f"cannot lock run file {self.run_path}: {exc.strerror}", received=str(self.path),
                               expected="a writable directory for the run file and its .lock sidecar") from exc
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "unknown"
            os.close(fd)
            raise StorageError("run file is being written by another coordinator", received=str(self.run_path),
                               expected=f"one coordinator per run file: stop the other one (pid {holder}) "
                                        "first") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        self._fd = fd
        return self

    @property
    def held(self) -> bool:
        return self._fd is not None

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # closing the descriptor drops the flock
            self._fd = None
