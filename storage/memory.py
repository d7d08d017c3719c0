"""InMemoryStorage: the trial table in numpy arrays, for tests and as the HDF5 writer's mirror."""

from __future__ import annotations

from typing import Any

import numpy as np

from protocol.errors import StorageError
from storage.base import BaseStorage
from storage.schema import RunMeta
from storage.table import TrialTable


class InMemoryStorage(BaseStorage):
    def __init__(self) -> None:
        self._meta: RunMeta | None = None
        self._table: TrialTable | None = None

    def create_run(self, meta: RunMeta) -> None:
        if self._meta is not None:
            raise StorageError("run already created", received=meta.run_id, expected="one run per store")
        self._meta = meta
        self._table = TrialTable(meta.n_params)

    def run_meta(self) -> RunMeta:
        if self._meta is None:
            raise StorageError("no run in this store", expected="create_run() first")
        return self._meta

    @property
    def table(self) -> TrialTable:
        if self._table is None:
            raise StorageError("no run in this store", expected="create_run() first")
        return self._table

    def _append(self, values: dict[str, Any]) -> None:
        self.table.append_row(values)

    def _update(self, trial_id: int, values: dict[str, Any]) -> None:
        self.table.set_row(trial_id, values)

    def columns(self) -> dict[str, np.ndarray]:
        return self.table.columns()
