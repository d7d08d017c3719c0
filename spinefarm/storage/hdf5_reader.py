"""Reading run files: whole tables (read_run, the loader behind spinefarm.load_run), metadata alone, the
episodes, a consistent snapshot; and Hdf5Reader, a lazy view for status queries (the API's read path).

Every read opens the file as an SWMR reader after checking its superblock's end of file, so a live
writer's file reads consistently and a truncated one fails at once instead of hanging.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path

import h5py
import numpy as np

from spinefarm.protocol.errors import StorageError
from spinefarm.storage import episodes as ep
from spinefarm.storage import evaluations as ev
from spinefarm.storage.base import BaseStorage
from spinefarm.storage.hdf5_layout import meta_of, write_run
from spinefarm.storage.probe import check_eof
from spinefarm.storage.schema import COLUMN_BY_NAME, COLUMNS, RunMeta, TrialRecord
from spinefarm.storage.table import EMPTY_STATUS, empty_value

# what damaged attributes or data raise from h5py
_DAMAGED = (KeyError, ValueError, TypeError, OSError, RuntimeError)


def _open(path: Path, swmr: bool = True) -> h5py.File:
    check_eof(path)  # a truncated file would hang an SWMR reader
    try:
        return h5py.File(path, "r", libver="latest", swmr=swmr)
    except OSError as exc:
        no_locks = "unable to lock file" in str(exc) and "No locks available" in str(exc)
        raise StorageError(f"cannot open run file {path}: {exc}", expected="a file system with locks, or "
                           "HDF5_USE_FILE_LOCKING=FALSE in the environment where it has none" if no_locks
                           else "a readable HDF5 file") from exc


def _damaged(path: Path, exc: BaseException, what: str = "") -> StorageError:
    return StorageError(f"cannot read {what}run file {path}: {str(exc).splitlines()[0][:200]}",
                        expected="an undamaged spinefarm run file")


def _must_exist(path: Path) -> None:
    if not path.is_file():
        message = "a folder is no run file" if path.is_dir() else "run file does not exist"
        raise StorageError(message, received=str(path), expected="an existing .h5 file")


def _rows(group: h5py.Group) -> int:
    return min(group[c.name].shape[0] for c in COLUMNS if c.name in group)


def _column(group: h5py.Group, name: str, sel: slice | list[int]) -> np.ndarray:
    """A column's rows `sel`; a column an older schema did not have (e.g. body_hash before schema 8) reads as
    its empty value, so older files open everywhere."""
    if name in group:
        return group[name][sel]
    return np.full(group["status"].shape[0], empty_value(name), dtype=COLUMN_BY_NAME[name].dtype)[sel]


def read_run(path: str | Path, swmr: bool = True) -> tuple[RunMeta, dict[str, np.ndarray]]:
    """Metadata and every complete row of a run file, also while (or after) a writer had it open.
    swmr=False: a file no writer has open (storage.probe), read once, so damage fails at once."""
    path = Path(path)
    _must_exist(path)
    with _open(path, swmr) as f:
        try:
            meta = meta_of(f, path)
            if "trials" not in f:
                raise StorageError(f"{path} has no /trials group", expected="a spinefarm run file")
            g = f["trials"]
            n = _rows(g)
            cols = {c.name: _column(g, c.name, slice(0, n)) for c in COLUMNS}
        except _DAMAGED as exc:
            raise _damaged(path, exc) from exc
    # A row the writer extended but had not filled yet has an empty status: cut the table there.
    empty = np.flatnonzero(cols["status"] == EMPTY_STATUS)
    if empty.size:
        cols = {k: v[: int(empty[0])] for k, v in cols.items()}
    return meta, cols


def read_meta(path: str | Path) -> RunMeta:
    """Only the run metadata (cheap: attributes, no table)."""
    path = Path(path)
    with _open(path) as f:
        try:
            return meta_of(f, path)
        except _DAMAGED as exc:
            raise _damaged(path, exc) from exc


def read_episodes(path: str | Path) -> dict[str, np.ndarray]:
    """The episodes table of a run file (storage.episodes), of its finished trials; empty for a plain run."""
    path = Path(path)
    _, cols = read_run(path)
    try:
        with h5py.File(path, "r", libver="latest", swmr=True) as f:
            episodes = ep.read_datasets(f)
    except _DAMAGED as exc:
        raise _damaged(path, exc, "the episodes of ") from exc
    return ep.of_finished(episodes, cols["status"], b"waiting")


def read_evaluations(path: str | Path) -> dict[str, np.ndarray]:
    """The evaluations table of a run file (storage.evaluations); empty for a file of an older schema."""
    path = Path(path)
    try:
        with _open(path) as f:
            return ev.read_datasets(f)
    except _DAMAGED as exc:
        raise _damaged(path, exc, "the evaluations of ") from exc


def schema_version(path: str | Path) -> int:
    """The schema version a run file was written at (storage.schema.OLDER_SCHEMA_VERSIONS: older ones)."""
    path = Path(path)
    with _open(path) as f:
        return int(f.attrs["file_schema_version"])


def snapshot(src: str | Path, dst: str | Path) -> int:
    """Consistent copy of a (possibly live) run file; returns the number of rows copied."""
    meta, cols = read_run(src)
    write_run(dst, meta, cols, read_episodes(src), evaluations=read_evaluations(src))
    return len(cols["trial_id"])


class _LazyColumns(Mapping):
    """Column name -> first n rows, read from the file on first use and kept."""

    def __init__(self, group: h5py.Group, n: int) -> None:
        self._group, self._n, self._cache = group, n, {}

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self._cache:
            self._cache[name] = _column(self._group, name, slice(0, self._n))
        return self._cache[name]

    def __iter__(self) -> Iterator[str]:
        return iter(c.name for c in COLUMNS)

    def __len__(self) -> int:
        return len(COLUMNS)


class Hdf5Reader(BaseStorage):
    """Read-only view of a (possibly live) run file for status queries: reads only what is asked.

    Status needs two small columns (status, objective) and a few rows, not the (n, n_params) parameter
    tables; this keeps an API request in milliseconds on runs of tens of thousands of trials.
    Close it (or use `with`) to release the file.
    """

    read_only = True

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        _must_exist(self.path)
        self._file = _open(self.path)
        try:
            self._meta = meta_of(self._file, self.path)
            self.file_schema_version = int(self._file.attrs["file_schema_version"])
            group = self._file["trials"]
            n = _rows(group)
            status = group["status"][:n]
            empty = np.flatnonzero(status == EMPTY_STATUS)  # rows extended but not yet filled by the writer
            self._n = int(empty[0]) if empty.size else n
            self._cols = _LazyColumns(group, self._n)
            self._cols._cache["status"] = status[: self._n]
        except _DAMAGED as exc:
            self._file.close()
            raise _damaged(self.path, exc) from exc
        except BaseException:
            self._file.close()
            raise

    def run_meta(self) -> RunMeta:
        return self._meta

    def columns(self) -> Mapping[str, np.ndarray]:  # type: ignore[override]
        return self._cols

    def n_trials(self) -> int:
        return self._n

    def trial(self, trial_id: int) -> TrialRecord:
        return self.records([trial_id])[0]

    def records(self, ids: Sequence[int]) -> list[TrialRecord]:
        """The trials `ids`, in that order, with one read per column (a row at a time is one per column and
        trial: seconds for a page of a thousand)."""
        if not len(ids):
            return []
        rows = sorted({int(i) for i in ids})
        if rows[0] < 0 or rows[-1] >= self._n:
            bad = [i for i in ids if not 0 <= i < self._n]
            raise StorageError("no such trial", received=bad[0] if len(bad) == 1 else bad[:5],
                               expected=f"0 <= id < {self._n}")
        group = self._file["trials"]
        if rows[-1] - rows[0] + 1 == len(rows):  # a run of ids: one slice
            cols = {c.name: _column(group, c.name, slice(rows[0], rows[-1] + 1)) for c in COLUMNS}
        else:  # h5py point selection needs increasing indices
            cols = {c.name: _column(group, c.name, rows) for c in COLUMNS}
        at = {tid: j for j, tid in enumerate(rows)}
        return [TrialRecord.from_columns(cols, at[int(tid)]) for tid in ids]

    def episodes(self, trial_id: int | None = None) -> dict[str, np.ndarray]:
        cols = ep.of_finished(ep.read_datasets(self._file), self._cols["status"], b"waiting")
        return cols if trial_id is None else ep.rows_of(cols, trial_id)

    def evaluations(self) -> dict[str, np.ndarray]:
        return ev.read_datasets(self._file)

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None
