"""Dependencies shared by the routers: the registry and a read-only view of one run."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

from fastapi import Depends, Request
from fastapi import Path as PathParam

from api.registry import RunRegistry
from storage.hdf5 import Hdf5Storage

RunId = Annotated[str, PathParam(pattern=r"^[A-Za-z0-9_.\-]{1,64}$", description="run id")]


def registry(request: Request) -> RunRegistry:
    return request.app.state.registry


def run_path(run_id: RunId, reg: Annotated[RunRegistry, Depends(registry)]) -> Path:
    return reg.path_of(run_id)


def run_storage(path: Annotated[Path, Depends(run_path)]) -> Hdf5Storage:
    """The run as it is on disk now (every flushed row), read-only."""
    return Hdf5Storage.open_read(path)
