"""One writer per run file, whatever name it is reached by: held while a coordinator writes.

Two locks, both released by the kernel when the holder dies (a SIGKILLed coordinator never leaves a
stale lock):

- the name lock: flock on the sidecar RUN.h5.lock beside the file's resolved path (symlinks followed),
  taken before the run file is looked at, so also a file that does not exist yet (`--overwrite`) has one
  writer;
- the identity lock: an open-file-description write lock (fcntl F_OFD_SETLK) on the run file itself,
  i.e. on its device and inode, so a hard link (or any other name of the same file) finds it held.
  OFD locks belong to the descriptor that took them, not to the process: HDF5 opening and closing the
  same file in this process does not drop them, and they do not interact with HDF5's own flock.
  `bind(path)` moves it to a new file (resume writes a fresh copy and renames it over the old one).

The sidecar stays in place: deleting a lock file races with its next taker. A file system that refuses
locks (ENOLCK: NFS without its lock service) refuses the run too, saying so, unless HDF5_USE_FILE_LOCKING=FALSE
says to go without: HDF5 then takes no lock either, and one writer is the user's to keep.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import logging
import os
import struct
from pathlib import Path

from spinefarm.protocol.errors import StorageError

log = logging.getLogger("spinefarm.storage")
_F_OFD_SETLK = getattr(fcntl, "F_OFD_SETLK", 37)
_NO_LOCKS = (errno.ENOLCK, errno.ENOSYS, errno.EOPNOTSUPP)  # flock refused by the file system itself
_FLOCK = "@hhqqi4x"   # struct flock: l_type, l_whence, l_start, l_len, l_pid (0 for OFD locks)


def lock_path(run_path: str | Path) -> Path:
    p = Path(run_path).resolve()
    return p.with_name(p.name + ".lock")


def locks_waived() -> bool:
    """HDF5_USE_FILE_LOCKING=FALSE: the user's word that this file system has no locks; HDF5 then takes none,
    and the run lock goes without its name lock where flock is refused."""
    return os.environ.get("HDF5_USE_FILE_LOCKING") in ("FALSE", "0")  # HDF5's own reading of it, to the letter


def _cannot_lock(run_path: Path, exc: OSError) -> StorageError:
    if exc.errno in _NO_LOCKS:
        return StorageError(f"cannot lock run file {run_path}: {exc.strerror} (its file system offers no locks: "
                            "NFS without its lock service, a Lustre mount without -o flock, some FUSE mounts)",
                            expected="the run file on a file system with locks (--out on a local disk), or "
                                     "HDF5_USE_FILE_LOCKING=FALSE in the environment to write it without "
                                     "(then only one coordinator may write it)")
    return StorageError(f"cannot lock run file {run_path}: {exc.strerror}", expected="a lockable run file")


def _refused(run_path: Path, holder: str) -> StorageError:
    return StorageError("run file is being written by another coordinator", received=str(run_path),
                        expected=f"one coordinator per run file: stop the other one ({holder}) first")


def _lock_identity(path: Path, run_path: Path) -> int | None:
    """An OFD write lock on the whole file at `path`; its descriptor (None: the file is not writable here,
    which the callers refuse on their own)."""
    try:
        fd = os.open(path, os.O_RDWR | os.O_CLOEXEC)
    except OSError:
        return None
    try:
        fcntl.fcntl(fd, _F_OFD_SETLK, struct.pack(_FLOCK, fcntl.F_WRLCK, os.SEEK_SET, 0, 0, 0))
    except OSError as exc:
        os.close(fd)
        if exc.errno in (11, 13):  # EAGAIN, EACCES: held by another descriptor
            st = os.stat(path)
            raise _refused(run_path, f"it holds this file, device {st.st_dev} inode {st.st_ino}, under "
                                     "another name or link") from None
        return None  # a file system without OFD locks: the name lock still holds
    return fd


class RunLock:
    """Held from `acquire()` until `release()` (or the process ends)."""

    def __init__(self, run_path: str | Path) -> None:
        self.run_path = Path(run_path)
        self.path = lock_path(run_path)
        self._fd: int | None = None
        self._ident_fd: int | None = None

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
            raise _refused(self.run_path, f"pid {holder}") from None
        except OSError as exc:
            if exc.errno not in _NO_LOCKS or not locks_waived():
                os.close(fd)
                raise _cannot_lock(self.run_path, exc) from None
            log.warning("run file %s is written without a lock (HDF5_USE_FILE_LOCKING=FALSE, a file system "
                        "without locks): make sure no other coordinator writes it", self.run_path)
        self._fd = fd
        try:
            if self.path.with_name(self.path.name[:-5]).exists():
                self.bind(self.path.with_name(self.path.name[:-5]))
        except BaseException:
            self.release()
            raise
        with contextlib.suppress(OSError):  # the holder's pid is for messages only (a full disk may refuse it)
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        return self

    def bind(self, file_path: str | Path) -> None:
        """Hold the identity lock on the file now at `file_path` (and drop the one held before)."""
        new = _lock_identity(Path(file_path), self.run_path)
        if self._ident_fd is not None:
            os.close(self._ident_fd)
        self._ident_fd = new

    @property
    def held(self) -> bool:
        return self._fd is not None

    def release(self) -> None:
        for name in ("_ident_fd", "_fd"):
            fd = getattr(self, name)
            if fd is not None:
                os.close(fd)  # closing the descriptor drops its lock
                setattr(self, name, None)
