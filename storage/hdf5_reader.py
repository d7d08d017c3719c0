"""Hdf5Reader: a read-only, lazy view of a run file for status queries (the API's read path)."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from pathlib import Path

import h5py
import numpy as np
from spinefarm.protocol.errors import StorageError
from spinefarm.storage.base import BaseStorage
from spinefarm.storage.hdf5 import _read_meta
from spinefarm.storage.probe import check_eof
from spinefarm.storage.schema import COLUMNS, RunMeta, TrialRecord
from spinefarm.storage.table import EMPTY_STATUS


class _LazyColumns(Mapping):
    """Column name -> first n rows, read from the file on first use and kept."""

    def __init__(self, group: h5py.Group, n: int) -> None:
        self._group, self._n, self._cache = group, n, {}

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self._cache:
            self._cache[name] = self._group[name][: self._n]
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
        if not self.path.is_file():
            raise StorageError("run file does not exist", received=str(path), expected="an existing .h5 file")
        check_eof(self.path)  # a truncated file would hang the SWMR open below
        try:
            self._file = h5py.File(self.path, "r", libver="latest", swmr=True)
        except OSError as exc:
            raise StorageError(f"cannot open run file {path}: {exc}", expected="a readable HDF5 file") from exc
        try:
            self._meta = _read_meta(self._file, self.path)
            group = self._file["trials"]
            n = min(group[c.name].shape[0] for c in COLUMNS)
            status = group["status"][:n]
            empty = np.flatnonzero(status == EMPTY_STATUS)  # rows extended but not yet filled by the writer
            self._n = int(empty[0]) if empty.size else n
            self._cols = _LazyColumns(group, self._n)
            self._cols._cache["status"] = status[: self._n]
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
        if not 0 <= trial_id < self._n:
            raise StorageError("no such trial", received=trial_id, expected=f"0 <= id < {self._n}")
        group = self._file["trials"]
        row = {c.name: group[c.name][trial_id : trial_id + 1] for c in COLUMNS}
        return TrialRecord.from_columns(row, 0)

    def best(self, k: int) -> list[TrialRecord]:
        ids = self.best_ids(k)
        if not ids:
            return []
        rows = sorted(ids)  # h5py point selection needs increasing indices: one read per column
        group = self._file["trials"]
        cols = {c.name: group[c.name][rows] for c in COLUMNS}
        at = {tid: j for j, tid in enumerate(rows)}
        return [TrialRecord.from_columns(cols, at[tid]) for tid in ids]

    def episodes(self, trial_id: int | None = None) -> dict[str, np.ndarray]:
        from spinefarm.storage import episodes as ep

        cols = ep.of_finished(ep.read_datasets(self._file), self._cols["status"], b"waiting")
        return cols if trial_id is None else ep.rows_of(cols, trial_id)

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None
