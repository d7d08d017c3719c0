"""Hdf5Storage: the single writer of one run file (layout: storage.hdf5_layout; readers: storage.hdf5_reader).

The writer keeps the table in memory, writes changed rows at `flush()` and runs in SWMR mode, so
readers (the API, a notebook) see every flushed row while the run goes on.

`flush()` ends with fsync: what it wrote is on the disk when it returns (it survives a power cut or
a crashed machine, not only a killed process), so the coordinator acknowledges a result only then.

A file whose SWMR writer was killed keeps its consistency flags set and then opens only for SWMR
reading; `resume()` therefore reads it that way and rewrites it to a fresh file (atomic replace)
instead of relying on external tools to clear the flags.
"""

from __future__ import annotations

import errno
import logging
import os
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np

from spinefarm.protocol.errors import StorageError
from spinefarm.storage import episodes as ep
from spinefarm.storage import evaluations as ev
from spinefarm.storage.file_ops import _fsync_dir, _quiet_failed_deallocs, _reason, _refuse_read_only, _trim
from spinefarm.storage.hdf5_layout import write_run
from spinefarm.storage.hdf5_reader import read_episodes, read_evaluations, read_run, schema_version
from spinefarm.storage.memory import InMemoryStorage
from spinefarm.storage.probe import probe, stored_eof
from spinefarm.storage.runlock import RunLock
from spinefarm.storage.schema import COLUMNS, RunMeta
from spinefarm.storage.table import TrialTable

WRITER_LOCK_WAIT_S = 10.0  # how long the writer's open waits for readers in the middle of opening the file
log = logging.getLogger(__name__)
# A file handle whose writes failed: closing it makes HDF5 retry the failed writes (and crash at exit),
# so it is kept here, never closed, and the process leaves with os._exit (see CoordinatorCore.write_failure).
_ABANDONED: list[h5py.File] = []
# The space a file grows into is written (zeros) and synced before HDF5 uses it. On ext4 a sync writes the
# data first and commits a new file size or new blocks afterwards: a disk dying in between would leave
# HDF5's new superblock in a file shorter than it says (seen: "truncated", every row unreadable). Inside
# the reserve a sync only overwrites blocks the file already has. Trimmed to HDF5's end at close.
RESERVE_B = 8 << 20      # reserved beyond HDF5's end when it is topped up
RESERVE_LOW_B = 4 << 20  # topped up when less than this is left (one flush grows the file far less)



def _replace_with_copy(real: Path, suffix: str, meta: RunMeta, cols: dict[str, np.ndarray],
                       episodes: dict[str, np.ndarray], live: bool, lock: RunLock | None,
                       evaluations: dict[str, np.ndarray]) -> None:
    """Write the run to `real` + suffix, sync it and rename it over `real`: atomic, so the old file stays
    intact until the new one is complete. The lock moves to the new file before it takes the name. A failed
    copy is removed and the error raised; the caller syncs the directory."""
    tmp = real.with_name(real.name + suffix)
    try:
        write_run(tmp, meta, cols, episodes, live=live, evaluations=evaluations)
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        if lock is not None:
            lock.bind(tmp)
        os.replace(tmp, real)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise

def _open_for_writing(path: Path) -> h5py.File:
    """The writer's open. HDF5 locks a file while it opens it, readers too: a reader opening a new or resumed
    run file (the API, a dashboard, spinefarm.load_run polling for results) in the instant the writer reopens
    it makes the writer's lock fail with EAGAIN. The RunLock already keeps other writers out, so wait that out;
    a process that keeps the file open without SWMR still fails after WRITER_LOCK_WAIT_S."""
    end = time.monotonic() + WRITER_LOCK_WAIT_S
    while True:
        try:
            return h5py.File(path, "r+", libver="latest")
        except BlockingIOError:
            if time.monotonic() > end:
                raise
            time.sleep(0.02)


class Hdf5Storage(InMemoryStorage):
    """The single writer of one run file. Use `create`, `resume` or `open_read`."""

    def __init__(self, path: Path, file: h5py.File | None, meta: RunMeta, table: TrialTable) -> None:
        super().__init__()
        self.path = path
        self._file = file
        self._meta = meta
        self._table = table
        self._rebuild_ranking()
        self.read_only = file is None
        self.write_error: str | None = None  # set once a write failed: nothing is written after it
        self.close_warning: str | None = None  # what close() could not do (compress) with every row stored
        self.fsync = True  # False: flush hands rows to the OS only (bench/coordinator_throughput.py compares)
        self._lock: RunLock | None = None
        self._datasets = {c.name: file["trials"][c.name] for c in COLUMNS} if file is not None else {}

    @classmethod
    def create(cls, path: str | Path, meta: RunMeta, overwrite: bool = False) -> Hdf5Storage:
        """A new run file; `overwrite` replaces an existing one, but never one another coordinator writes."""
        from spinefarm.storage.status import status_path

        path = Path(path)
        lock = RunLock(path).acquire()  # before looking: the file may be live
        try:
            if path.exists() and not overwrite:
                raise StorageError("run file already exists", received=str(path),
                                   expected="a new path (or --resume to continue it, --overwrite to replace it)")
            _refuse_read_only(path)
            path.unlink(missing_ok=True)
            status_path(path).unlink(missing_ok=True)
            meta = meta.opened("create")
            write_run(path, meta, TrialTable(meta.n_params).columns(), live=True)
            lock.bind(path)  # the new file's identity: a link to it is refused too
            _fsync_dir(path)  # the new name too must survive a power cut
            return cls._open_writer(path, meta, TrialTable(meta.n_params), lock)
        except BaseException:
            lock.release()
            raise

    @classmethod
    def resume(cls, path: str | Path, trials_budget: int | None = None,
               seed_of: Callable[[int, np.ndarray], np.ndarray] | None = None) -> Hdf5Storage:
        """Reopen a run for writing, whether it was closed cleanly or its writer was killed.

        trials_budget: a new budget (not below the parameter sets already sampled), else the stored one.
        Every stored row is validated first (storage.validate; `seed_of(run_seed, trial_ids)` gives the
        seeds the run derives); a file that fails is left untouched.
        """
        from spinefarm.storage.validate import validate_rows

        path = Path(path)
        lock = RunLock(path).acquire()
        try:
            _refuse_read_only(path)
            probe(path)  # a damaged file gives a clear error within seconds, never a hang
            meta, cols = read_run(path)
            validate_rows(path, meta, cols, seed_of)
            if trials_budget is not None:
                # the budget counts parameter sets: a multi-fidelity run's promotions re-run rung-0 rows
                n = int(np.count_nonzero(cols["rung"] == 0))
                if trials_budget < max(n, 1):
                    raise StorageError("new trial budget is below the trials already sampled (parameter sets; "
                                       "promoted re-runs do not count)", received=trials_budget,
                                       expected=f"at least {max(n, 1)}")
                meta = replace(meta, trials_budget=trials_budget)
            meta = meta.opened("resume")   # a copy resumed elsewhere gets its own instance too
            episodes, evaluations = read_episodes(path), read_evaluations(path)
            ev.check_kinds(evaluations, path)   # before anything is written
            real = path.resolve()  # a symlink stays a symlink: its target is what gets replaced
            real.with_name(real.name + ".compress-tmp").unlink(missing_ok=True)  # a close cut short
            try:
                _replace_with_copy(real, ".resume-tmp", meta, cols, episodes, live=True, lock=lock,
                                   evaluations=evaluations)
            except OSError as exc:
                raise StorageError(f"cannot write the resumed copy of {path}: {_reason(exc)}",
                                   expected="room for a copy of the run file beside it") from exc
            _fsync_dir(real)
            table = TrialTable(meta.n_params, capacity=max(1024, len(cols["trial_id"])))
            table.load(cols)
            storage = cls._open_writer(path, meta, table, lock)
            storage._episodes.load(episodes)
            storage._evaluations.load(evaluations)
            storage._rebuild_ranking()   # a COT objective ranks a judged set by its judge's COT
            return storage
        except BaseException:
            lock.release()
            raise

    @classmethod
    def _open_writer(cls, path: Path, meta: RunMeta, table: TrialTable, lock: RunLock) -> Hdf5Storage:
        try:
            f = _open_for_writing(path)
            f.swmr_mode = True  # from here on no new objects or attributes; readers may attach
        except BlockingIOError as exc:
            raise StorageError(f"cannot open run file {path} for writing: another process holds it open "
                               f"without SWMR ({_reason(exc)})", expected="no other process with the file open "
                               "(readers of a run file open it with swmr=True, as spinefarm.load_run does)") from exc
        except OSError as exc:
            raise StorageError(f"cannot open run file {path} for writing: {_reason(exc)}",
                               expected="a writable file system") from exc
        storage = cls(path, f, meta, table)
        storage._lock = lock
        try:
            storage._reserve()
        except OSError as exc:
            f.close()
            raise StorageError(f"cannot open run file {path} for writing: {_reason(exc)}",
                               expected="a working, writable file system with free space") from exc
        return storage

    @classmethod
    def open_read(cls, path: str | Path) -> Hdf5Storage:
        """A read-only in-memory snapshot of the file as it is now (probed first: never hangs)."""
        if Path(path).is_file():
            probe(path)
        meta, cols = read_run(path)
        table = TrialTable(meta.n_params, capacity=max(1, len(cols["trial_id"])))
        table.load(cols)
        storage = cls(Path(path), None, meta, table)
        storage._episodes.load(read_episodes(path))
        storage._evaluations.load(read_evaluations(path))
        storage._rebuild_ranking()   # a COT objective ranks a judged set by its judge's COT
        storage.file_schema_version = schema_version(path)
        return storage

    def create_run(self, meta: RunMeta) -> None:
        raise StorageError("an Hdf5Storage holds its run already", expected="Hdf5Storage.create(path, meta)")

    def flush(self) -> None:
        """Write changed rows, flush HDF5 and fsync the file: on return they are on the disk.

        One fsync per call, however many rows changed, so a batch of results costs one disk round trip.
        Raises StorageError when a write, the flush or the fsync fails (disk full, I/O error, a file
        system shut down); from then on every flush raises the same error and nothing more is written.
        """
        if self.write_error is not None:
            raise StorageError(self.write_error, expected="a working, writable file system with free space")
        if self._file is None:
            return
        if not self.table.dirty and self._datasets["trial_id"].shape[0] == self.table.n and \
                self._evaluations.n == self._evaluations.n_written:
            return
        try:
            self._write_dirty()
        except Exception as exc:
            self.write_error = f"cannot write run file {self.path}: {_reason(exc)}"
            _quiet_failed_deallocs()
            raise StorageError(self.write_error, expected="a working, writable file system with free space") from exc

    def _write_dirty(self) -> None:
        n = self.table.n
        cols = self.table.columns()
        rows = np.array(sorted(self.table.dirty), dtype=np.int64)
        self.table.dirty.clear()
        ep.write_new(self._file, self._episodes)  # a finished trial's episodes before its status
        ev.write_new(self._file, self._evaluations)  # a judge's run before the verdict it gives
        # Fill rows before extending the status column, so a reader never sees a half-written row.
        for c in COLUMNS:
            ds = self._datasets[c.name]
            if c.name != "status" and ds.shape[0] < n:
                ds.resize(n, axis=0)
        runs = np.split(rows, np.flatnonzero(np.diff(rows) != 1) + 1) if rows.size else []
        for c in COLUMNS:
            if c.name == "status":
                continue
            for run in runs:
                a, b = int(run[0]), int(run[-1]) + 1
                self._datasets[c.name][a:b] = cols[c.name][a:b]
        # The rows' data reach the file before their status says complete: one flush of both could land
        # its chunks in any order, and a process killed inside it left a "complete" row of NaNs.
        self._file.flush()
        status = self._datasets["status"]
        if status.shape[0] < n:
            status.resize(n, axis=0)
        for run in runs:
            a, b = int(run[0]), int(run[-1]) + 1
            status[a:b] = cols["status"][a:b]
        self._file.flush()
        if self.fsync:  # sec2, HDF5's default driver, writes through this descriptor
            os.fsync(self._file.id.get_vfd_handle())
            self._reserve()

    def _reserve(self) -> None:
        """Keep at least RESERVE_LOW_B of written, synced zeros beyond HDF5's end of file (see RESERVE_B)."""
        if not self.fsync or self._file is None:
            return
        fd = self._file.id.get_vfd_handle()
        end = stored_eof(os.pread(fd, 2048 + 48, 0))
        size = os.fstat(fd).st_size
        if end is None or size - end >= RESERVE_LOW_B:
            return
        target = end + RESERVE_B  # zeros written ~ the file's growth: a bounded extra write
        zeros = bytes(1 << 20)
        try:
            while size < target:  # written, not ftruncate'd or fallocate'd: those leave blocks to commit
                size += os.pwrite(fd, zeros[: target - size], size)
        except OSError as exc:
            if exc.errno != errno.ENOSPC:
                raise
            # A nearly full disk: what was reserved is still HDF5's to use; once that is used up,
            # HDF5's own write fails with "No space left on device" and the run stops.
        os.fsync(fd)

    def _compress(self) -> None:
        """Replace the closed live file by a compressed copy of what it holds (atomically, under the lock). The
        live file stays as it is if the copy cannot be made: it is complete, only larger."""
        real = self.path.resolve()
        try:
            meta, cols = read_run(real)  # what the file holds, not what memory says it should
            _replace_with_copy(real, ".compress-tmp", meta, cols, read_episodes(real), live=False, lock=self._lock,
                               evaluations=read_evaluations(real))
            _fsync_dir(real)
        except (OSError, StorageError, ValueError) as exc:
            self.close_warning = f"run file {self.path} left uncompressed ({_reason(exc)}): it is complete, only larger"
            log.info(self.close_warning)

    def close(self) -> None:
        try:
            if self._file is not None:
                if self.write_error is None:
                    self.flush()
                    self._file.close()
                    _trim(self.path)
                    self._compress()
                else:
                    _ABANDONED.append(self._file)
                    self._datasets = {}
                self._file = None
                self.read_only = True
        finally:
            if self._lock is not None:
                self._lock.release()
                self._lock = None
