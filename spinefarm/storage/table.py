"""Growable in-memory columns of the trial table (numpy arrays, capacity doubled on demand)."""

from __future__ import annotations

import numpy as np

from spinefarm.storage.schema import COLUMNS, VECTOR_COLUMNS

EMPTY_STATUS = b""  # a row extended in a file but not yet written


def empty_value(name: str) -> object:
    dtype = next(c.dtype for c in COLUMNS if c.name == name)
    if dtype.startswith("S"):
        return b""
    if name in ("parent",):
        return -1
    return np.nan if dtype.startswith("f") else 0


class TrialTable:
    """Columns of length `n`; `dirty` holds row indices changed since the last flush."""

    def __init__(self, n_params: int, capacity: int = 1024) -> None:
        self.n_params = n_params
        self.n = 0
        self.dirty: set[int] = set()
        self._cols = {c.name: self._alloc(c.name, c.dtype, capacity) for c in COLUMNS}

    def _alloc(self, name: str, dtype: str, capacity: int) -> np.ndarray:
        shape = (capacity, self.n_params) if name in VECTOR_COLUMNS else (capacity,)
        arr = np.empty(shape, dtype=dtype)
        arr[...] = empty_value(name)
        return arr

    def _grow(self, needed: int) -> None:
        cap = len(self._cols["trial_id"])
        if needed <= cap:
            return
        new_cap = max(needed, 2 * cap)
        for c in COLUMNS:
            new = self._alloc(c.name, c.dtype, new_cap)
            new[: self.n] = self._cols[c.name][: self.n]
            self._cols[c.name] = new

    def append_row(self, values: dict[str, object]) -> int:
        i = self.n
        self._grow(i + 1)
        self.n = i + 1
        self.set_row(i, values)
        return i

    def set_row(self, i: int, values: dict[str, object]) -> None:
        for name, v in values.items():
            self._cols[name][i] = v
        self.dirty.add(i)

    def get(self, name: str, i: int) -> object:
        return self._cols[name][i]

    def columns(self) -> dict[str, np.ndarray]:
        """Views of the first n rows (do not modify)."""
        return {name: arr[: self.n] for name, arr in self._cols.items()}

    def load(self, cols: dict[str, np.ndarray]) -> None:
        """Replace the contents with `cols` (all of equal length), nothing dirty."""
        n = len(cols["trial_id"])
        self.n = 0
        self._grow(n)
        for c in COLUMNS:
            self._cols[c.name][:n] = cols[c.name]
        self.n = n
        self.dirty.clear()
