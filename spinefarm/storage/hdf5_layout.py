"""How a run lives in an HDF5 file: run metadata as root attributes, one chunked dataset per column.

Root attributes hold the run metadata (JSON strings for nested values); group /trials holds one chunked,
resizable dataset per column (see storage.schema), row i = trial i, with `unit` and `description`
attributes. The writer (storage.hdf5) and the readers (storage.hdf5_reader) both go through here.
"""

from __future__ import annotations

import json
from dataclasses import fields
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from spinefarm.protocol.envelope import SCHEMA_VERSION
from spinefarm.protocol.errors import SpinefarmError, StorageError
from spinefarm.protocol.settings import RunSettings
from spinefarm.storage import episodes as ep
from spinefarm.storage import evaluations as ev
from spinefarm.storage.schema import COLUMNS, FILE_SCHEMA_VERSION, OLDER_SCHEMA_VERSIONS, VECTOR_COLUMNS, RunMeta
from spinefarm.storage.table import empty_value

CHUNK_ROWS = 1024
# Chunks are mostly fill values and repeated bytes early in a run: gzip (with byte shuffling, which
# groups the bytes of floats) shrinks an 8-trial file from 2.5 MB to about 0.1 MB; readers need nothing extra.
COMPRESSION = {"compression": "gzip", "compression_opts": 4, "shuffle": True}
_JSON_FIELDS = ("sampler", "settings", "run", "environment", "instances")
_TUPLE_FIELDS = ("param_names", "param_lows", "param_highs", "param_units")


def write_meta(f: h5py.File, meta: RunMeta) -> None:
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


def meta_of(f: h5py.File, path: Path) -> RunMeta:
    """The run metadata, checked against the table it describes: a file edited by hand (or by another tool)
    gives one StorageError naming what does not fit, never a traceback further on."""
    if f.attrs.get("file_schema_version") not in (FILE_SCHEMA_VERSION, *OLDER_SCHEMA_VERSIONS):
        raise StorageError(f"{path} is not a spinefarm run file of this version",
                           received=f.attrs.get("file_schema_version"),
                           expected=f"{FILE_SCHEMA_VERSION} (or an older {OLDER_SCHEMA_VERSIONS})")
    try:
        meta = _parse_meta(f)
    except (KeyError, ValueError, TypeError, SpinefarmError) as exc:
        raise StorageError(f"run file {path} has unreadable metadata: {str(exc).splitlines()[0][:200]}",
                           expected="the attributes a spinefarm run file is written with") from exc
    _check_shapes(f, meta, path)
    return meta


def _check_shapes(f: h5py.File, meta: RunMeta, path: Path) -> None:
    """Every parameter attribute names the same parameters, as many as the table's parameter columns."""
    counts = {name: len(getattr(meta, name)) for name in _TUPLE_FIELDS}
    trials = f.get("trials")
    for name in VECTOR_COLUMNS:
        ds = trials.get(name) if isinstance(trials, h5py.Group) else None
        if isinstance(ds, h5py.Dataset) and len(ds.shape) == 2:
            counts[f"/trials/{name} columns"] = int(ds.shape[1])
    if len(set(counts.values())) > 1:
        raise StorageError(f"run file {path} does not fit together: its parameter attributes and columns "
                           "disagree", received=", ".join(f"{k} {v}" for k, v in counts.items()),
                           expected=f"{counts['param_names']} everywhere (one per parameter name)")


def _parse_meta(f: h5py.File) -> RunMeta:
    kw: dict[str, Any] = {}
    for fld in fields(RunMeta):
        if fld.name in ("environment", "instances") and fld.name not in f.attrs:
            continue  # written before runs recorded them
        raw = f.attrs[fld.name]
        if fld.name == "settings":
            kw[fld.name] = RunSettings.from_dict(_json(raw, fld.name))
        elif fld.name == "instances":
            kw[fld.name] = _instances(_json(raw, fld.name))
        elif fld.name in _JSON_FIELDS:
            kw[fld.name] = _json(raw, fld.name)
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


def _json(raw: Any, name: str) -> Any:
    try:
        return json.loads(raw)
    except ValueError as exc:   # say which attribute: the JSON error alone names none
        raise ValueError(f"attribute {name} is not JSON ({exc})") from exc


def _instances(raw: Any) -> tuple[dict[str, Any], ...]:
    if not isinstance(raw, list) or not all(isinstance(e, dict) and isinstance(e.get("instance"), str) for e in raw):
        raise ValueError(f"attribute instances is not a list of {{'instance': ...}} entries: {str(raw)[:80]}")
    return tuple(raw)


def create_datasets(f: h5py.File, n_params: int, n_rows: int, compressed: bool = True) -> dict[str, h5py.Dataset]:
    g = f.create_group("trials")
    out = {}
    for c in COLUMNS:
        vec = c.name in VECTOR_COLUMNS
        ds = g.create_dataset(
            c.name, shape=(n_rows, n_params) if vec else (n_rows,), dtype=c.dtype,
            maxshape=(None, n_params) if vec else (None,),
            chunks=(CHUNK_ROWS, max(n_params, 1)) if vec else (CHUNK_ROWS,),
            fillvalue=empty_value(c.name), **(COMPRESSION if compressed else {}))
        ds.attrs["unit"] = c.unit
        ds.attrs["description"] = c.description
        out[c.name] = ds
    return out


def write_run(path: str | Path, meta: RunMeta, cols: dict[str, np.ndarray],
              episodes: dict[str, np.ndarray] | None = None, live: bool = False,
              evaluations: dict[str, np.ndarray] | None = None) -> None:
    """Write a complete, closed (non-SWMR) run file: used for snapshots, for a finished run and for resume.
    episodes, evaluations: the episodes and evaluations tables (storage.episodes, storage.evaluations; none:
    empty). The file is written at the current schema version, whatever the version it was read from.

    live: the file a writer will go on appending to, in SWMR mode, whose chunks are not compressed. SWMR never
    reuses freed space, and a compressed chunk is written anew at each flush, so a live compressed file grew
    by every column's last chunk at every flush (a 2,888-trial run: 200 MB for 1 MB of rows). A writer
    compresses its file when it closes."""
    n = len(cols["trial_id"])
    with h5py.File(path, "w", libver="latest") as f:
        write_meta(f, meta)
        for name, ds in create_datasets(f, meta.n_params, n, compressed=not live).items():
            if n:
                ds[:] = cols[name]
        ep.create_datasets(f, ep.empty_columns() if episodes is None else episodes, {} if live else COMPRESSION)
        ev.create_datasets(f, ev.empty_columns() if evaluations is None else evaluations,
                           {} if live else COMPRESSION)

