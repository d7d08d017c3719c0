"""A run file's side tables (/episodes, /evaluations): rows keyed to trial rows, in a group of their own.

Their columns, empty values and HDF5 handling are one mechanism: a row is extended, then filled with status last,
so a reader cuts the table at the first row whose status is still empty.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from spinefarm.protocol.columns import Column


def empty_value(dtype: str) -> Any:
    """What an unfilled cell holds: b"" for text, -1 for integers (no row), NaN otherwise."""
    return b"" if dtype.startswith("S") else (-1 if dtype.startswith("i") else np.nan)


def empty_columns(columns: Sequence[Column], n: int = 0) -> dict[str, np.ndarray]:
    out = {}
    for c in columns:
        out[c.name] = np.empty(n, dtype=c.dtype)
        out[c.name][...] = empty_value(c.dtype)
    return out


def create_group(f: Any, group: str, columns: Sequence[Column], cols: dict[str, np.ndarray],
                 compression: dict[str, Any], chunk_rows: int) -> None:
    """The group with `cols` written (its datasets exist before SWMR mode forbids new objects)."""
    g = f.create_group(group)
    n = len(cols["trial_id"])
    for c in columns:
        ds = g.create_dataset(c.name, shape=(n,), dtype=c.dtype, maxshape=(None,), chunks=(chunk_rows,),
                              fillvalue=empty_value(c.dtype), **compression)
        ds.attrs["unit"], ds.attrs["description"] = c.unit, c.description
        if n:
            ds[:] = cols[c.name]


def read_group(f: Any, group: str, columns: Sequence[Column]) -> dict[str, np.ndarray]:
    """Every fully written row (none for a file from before the group)."""
    if group not in f:
        return empty_columns(columns)
    g = f[group]
    n = min(g[c.name].shape[0] for c in columns if c.name in g)
    # a column added since the file was written reads as its empty value (NaN: not measured)
    cols = {c.name: g[c.name][:n] if c.name in g else empty_columns((c,), n)[c.name] for c in columns}
    empty = np.flatnonzero(cols["status"] == b"")  # extended, not yet filled: cut there
    return {k: v[: int(empty[0])] for k, v in cols.items()} if empty.size else cols


def append_rows(f: Any, group: str, cols: dict[str, np.ndarray], a: int, b: int) -> None:
    """Rows [a, b) of `cols` into the file, status last (a half-written row is never read)."""
    g = f[group]
    for name in (*(n for n in cols if n != "status"), "status"):
        if g[name].shape[0] < b:
            g[name].resize(b, axis=0)
        g[name][a:b] = cols[name][a:b]
