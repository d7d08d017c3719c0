"""Dependencies shared by the routers: the registry and a read-only view of one run."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Annotated

from fastapi import Depends, Request
from fastapi import Path as PathParam

from spinefarm.api.registry import RunRegistry
from spinefarm.storage.hdf5_reader import Hdf5Reader

RunId = Annotated[str, PathParam(pattern=r"^[A-Za-z0-9_.\-]{1,64}$", description="run id")]


def registry(request: Request) -> RunRegistry:
    return request.app.state.registry


def run_path(run_id: RunId, reg: Annotated[RunRegistry, Depends(registry)]) -> Path:
    return reg.path_of(run_id)


def run_storage(path: Annotated[Path, Depends(run_path)]) -> Iterator[Hdf5Reader]:
    """The run as it is on disk now (every flushed row), read-only, released after the request."""
    reader = Hdf5Reader(path)
    try:
        yield reader
    finally:
        reader.close()
