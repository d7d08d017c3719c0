"""Hdf5Storage: one self-describing HDF5 file per run, single writer, SWMR readers.

Layout: root attributes hold the run metadata (JSON strings for nested values); group /trials holds
one chunked, resizable dataset per column (see storage.schema), row i = trial i, with `unit` and
`description` attributes. The writer keeps the table in memory, writes changed rows at `flush()`
and runs in SWMR mode, so readers (the API, a notebook) see every flushed row while the run goes on.

`flush()` ends with fsync: what it wrote is on the disk when it returns (it survives a power cut or
a crashed machine, not only a killed process), so the coordinator acknowledges a result only then.

A file whose SWMR writer was killed keeps its consistency flags set and then opens only for SWMR
reading; `resume()` therefore reads it that way and rewrites it to a fresh file (atomic replace)
instead of relying on external tools to clear the flags.
"""

from __future__ import annotations

import errno
import json
import os
from collections.abc import Callable
from dataclasses import fields, replace
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from spinefarm.protocol.envelope import SCHEMA_VERSION
from spinefarm.protocol.errors import StorageError
from spinefarm.protocol.settings import RunSettings
from spinefarm.storage import episodes as ep
from spinefarm.storage.file_ops import _fsync_dir, _quiet_failed_deallocs, _reason, _refuse_read_only, _trim
from spinefarm.storage.memory import InMemoryStorage
from spinefarm.storage.probe import check_eof, probe, stored_eof
from spinefarm.storage.runlock import RunLock
from spinefarm.storage.schema import COLUMNS, FILE_SCHEMA_VERSION, VECTOR_COLUMNS, RunMeta
from spinefarm.storage.table import EMPTY_STATUS, TrialTable, empty_value

CHUNK_ROWS = 1024
# A file handle whose writes failed: closing it makes HDF5 retry the failed writes (and crash at exit),
# so it is kept here, never closed, and the process leaves with os._exit (see CoordinatorCore.write_failure).
_ABANDONED: list[h5py.File] = []
# Chunks are mostly fill values and repeated bytes early in a run: gzip (with byte shuffling, which
# groups the bytes of floats) shrinks an 8-trial file from 2.5 MB to about 0.1 MB; readers need nothing extra.
COMPRESSION = {"compression": "gzip", "compression_opts": 4, "shuffle": True}
# The space a file grows into is written (zeros) and synced before HDF5 uses it. On ext4 a sync writes the
# data first and commits a new file size or new blocks afterwards: a disk dying in between would leave
# HDF5's new superblock in a file shorter than it says (seen: "truncated", every row unreadable). Inside
# the reserve a sync only overwrites blocks the file already has. Trimmed to HDF5's end at close.
RESERVE_B = 8 << 20      # reserved beyond HDF5's end when it is topped up
RESERVE_LOW_B = 4 << 20  # topped up when less than this is left (one flush grows the file far less)
_JSON_FIELDS = ("sampler", "settings", "run", "environment")
_TUPLE_FIELDS = ("param_names", "param_lows", "param_highs", "param_units")


def _write_meta(f: h5py.File, meta: RunMeta) -> None:
    f.attrs["title"] = f"spinefarm run {meta.run_id}"
    f.attrs["description"] = (
        "Gait search for a tensegrity robot. Group /trials holds one dataset per column, one row per "
        "trial (row i = trial i); status 'waiting' rows were sampled but have no result yet. Parameter "
        "columns are named by param_names with bounds param_lows/param_highs in param_units.")
    f.attrs["file_schema_version"] = FILE_SCHEMA_VERSION
    f.attrs["message_schema_version"] = SCHEMA_VERSION
    for fld in fields(RunMeta):
        value = getattr(meta, fld.name)
        if fld.name in _JSON_FIELDS:
            f.attrs[fld.name] = json.dumps(value.to_dict() if fld.name == "settings" else value, sort_keys=True)
        elif fld.name in _TUPLE_FIELDS:
            f.attrs[fld.name] = np.array(value, dtype=h5py.string_dtype() if "names" in fld.name
                                         or "units" in fld.name else float)
        elif value is None:
            f.attrs[fld.name] = ""
        else:
            f.attrs[fld.name] = value


def _read_meta(f: h5py.File, path: Path) -> RunMeta:
    if f.attrs.get("file_schema_version") != FILE_SCHEMA_VERSION:
        raise StorageError(f"{path} is not a spinefarm run file of this version",
                           received=f.attrs.get("file_schema_version"), expected=FILE_SCHEMA_VERSION)
    kw: dict[str, Any] = {}
    for fld in fields(RunMeta):
        if fld.name == "environment" and fld.name not in f.attrs:
            continue  # written before runs recorded one
        raw = f.attrs[fld.name]
        if fld.name == "settings":
            kw[fld.name] = RunSettings.from_dict(json.loads(raw))
        elif fld.name in _JSON_FIELDS:
            kw[fld.name] = json.loads(raw)
        elif fld.name in ("param_names", "param_units"):
            kw[fld.name] = tuple(x.decode("utf-8", "replace") if isinstance(x, bytes) else str(x) for x in raw)
        elif fld.name in ("param_lows", "param_highs"):
            kw[fld.name] = tuple(float(x) for x in raw)
        elif fld.name == "controller":
            kw[fld.name] = str(raw) or None
        elif fld.name in ("seed", "trials_budget"):
            kw[fld.name] = int(raw)
        elif fld.name == "created_at_unix_s":
            kw[fld.name] = float(raw)
        else:
            kw[fld.name] = raw.decode("utf-8", "replace") if isinstance(raw, bytes) else str(raw)
    return RunMeta(**kw)


def _create_datasets(f: h5py.File, n_params: int, n_rows: int) -> dict[str, h5py.Dataset]:
    g = f.create_group("trials")
    out = {}
    for c in COLUMNS:
        vec = c.name in VECTOR_COLUMNS
        ds = g.create_dataset(
            c.name, shape=(n_rows, n_params) if vec else (n_rows,), dtype=c.dtype,
            maxshape=(None, n_params) if vec else (None,),
            chunks=(CHUNK_ROWS, max(n_params, 1)) if vec else (CHUNK_ROWS,),
            fillvalue=empty_value(c.name), **COMPRESSION)
        ds.attrs["unit"] = c.unit
        ds.attrs["description"] = c.description
        out[c.name] = ds
    return out


def read_run(path: str | Path) -> tuple[RunMeta, dict[str, np.ndarray]]:
    """Metadata and every complete row of a run file, also while (or after) a writer had it open."""
    path = Path(path)
    if not path.is_file():
        raise StorageError("run file does not exist", received=str(path), expected="an existing .h5 file")
    check_eof(path)  # a truncated file would hang an SWMR reader
    try:
        f = h5py.File(path, "r", libver="latest", swmr=True)
    except OSError as exc:
        raise StorageError(f"cannot open run file {path}: {exc}", expected="a readable HDF5 file") from exc
    with f:
        try:
            meta = _read_meta(f, path)
            if "trials" not in f:
                raise StorageError(f"{path} has no /trials group", expected="a spinefarm run file")
            g = f["trials"]
            n = min(g[c.name].shape[0] for c in COLUMNS)
            cols = {c.name: g[c.name][:n] for c in COLUMNS}
        except (KeyError, ValueError, TypeError, OSError, RuntimeError) as exc:  # damaged attributes or data
            raise StorageError(f"cannot read run file {path}: {str(exc).splitlines()[0][:200]}",
                               expected="an undamaged spinefarm run file") from exc
    # A row the writer extended but had not filled yet has an empty status: cut the table there.
    empty = np.flatnonzero(cols["status"] == EMPTY_STATUS)
    if empty.size:
        cols = {k: v[: int(empty[0])] for k, v in cols.items()}
    return meta, cols


def read_meta(path: str | Path) -> RunMeta:
    """Only the run metadata (cheap: attributes, no table)."""
    path = Path(path)
    check_eof(path)
    try:
        f = h5py.File(path, "r", libver="latest", swmr=True)
    except (OSError, FileNotFoundError) as exc:
        raise StorageError(f"cannot open run file {path}: {exc}", expected="a readable HDF5 file") from exc
    with f:
        try:
            return _read_meta(f, path)
        except (KeyError, ValueError, TypeError, OSError, RuntimeError) as exc:
            raise StorageError(f"cannot read run file {path}: {str(exc).splitlines()[0][:200]}",
                               expected="an undamaged spinefarm run file") from exc


def write_run(path: str | Path, meta: RunMeta, cols: dict[str, np.ndarray],
              episodes: dict[str, np.ndarray] | None = None) -> None:
    """Write a complete, closed (non-SWMR) run file: used for snapshots and for resume. episodes: the
    episodes table (storage.episodes; none: empty)."""
    n = len(cols["trial_id"])
    with h5py.File(path, "w", libver="latest") as f:
        _write_meta(f, meta)
        for name, ds in _create_datasets(f, meta.n_params, n).items():
            if n:
                ds[:] = cols[name]
        ep.create_datasets(f, ep.empty_columns() if episodes is None else episodes, COMPRESSION)


def read_episodes(path: str | Path) -> dict[str, np.ndarray]:
    """The episodes table of a run file (storage.episodes), of its finished trials; empty for a plain run."""
    _, cols = read_run(path)
    try:
        with h5py.File(path, "r", libver="latest", swmr=True) as f:
            episodes = ep.read_datasets(f)
    except (KeyError, ValueError, TypeError, OSError, RuntimeError) as exc:
        raise StorageError(f"cannot read the episodes of run file {path}: {str(exc).splitlines()[0][:200]}",
                           expected="an undamaged spinefarm run file") from exc
    return ep.of_finished(episodes, cols["status"], b"waiting")


def snapshot(src: str | Path, dst: str | Path) -> int:
    """Consistent copy of a (possibly live) run file; returns the number of rows copied."""
    meta, cols = read_run(src)
    write_run(dst, meta, cols, read_episodes(src))
    return len(cols["trial_id"])


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
            write_run(path, meta, TrialTable(meta.n_params).columns())
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
            episodes = read_episodes(path)
            real = path.resolve()  # a symlink stays a symlink: its target is what gets replaced
            tmp = real.with_name(real.name + ".resume-tmp")
            try:
                write_run(tmp, meta, cols, episodes)
                with open(tmp, "rb") as fh:
                    os.fsync(fh.fileno())
                lock.bind(tmp)  # held on the new file before it takes the name
                os.replace(tmp, real)  # atomic: the old file stays intact until the new one is complete
            except BaseException as exc:
                tmp.unlink(missing_ok=True)
                if isinstance(exc, OSError):
                    raise StorageError(f"cannot write the resumed copy of {path}: {_reason(exc)}",
                                       expected="room for a copy of the run file beside it") from exc
                raise
            _fsync_dir(real)
            table = TrialTable(meta.n_params, capacity=max(1024, len(cols["trial_id"])))
            table.load(cols)
            storage = cls._open_writer(path, meta, table, lock)
            storage._episodes.load(episodes)
            return storage
        except BaseException:
            lock.release()
            raise

    @classmethod
    def _open_writer(cls, path: Path, meta: RunMeta, table: TrialTable, lock: RunLock) -> Hdf5Storage:
        try:
            f = h5py.File(path, "r+", libver="latest")
            f.swmr_mode = True  # from here on no new objects or attributes; readers may attach
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
        if not self.table.dirty and self._datasets["trial_id"].shape[0] == self.table.n:
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

    def close(self) -> None:
        try:
            if self._file is not None:
                if self.write_error is None:
                    self.flush()
                    self._file.close()
                    _trim(self.path)
                else:
                    _ABANDONED.append(self._file)
                    self._datasets = {}
                self._file = None
                self.read_only = True
        finally:
            if self._lock is not None:
                self._lock.release()
                self._lock = None
