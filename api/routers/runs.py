"""GET /runs and /runs/{run_id}: runs and their status."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

from fastapi import APIRouter, Depends

from api.deps import registry, run_path, run_storage
from api.registry import RunRegistry
from api.schemas import RunStatus
from api.views import run_view
from protocol.errors import StorageError
from storage.hdf5_reader import Hdf5Reader

router = APIRouter(prefix="/runs", tags=["runs"])


@router.get("", response_model=list[RunStatus], summary="Every run and its status")
def list_runs(reg: Annotated[RunRegistry, Depends(registry)]) -> list[dict[str, Any]]:
    out = []
    for path in reg.runs().values():
        try:
            with Hdf5Reader(path) as reader:
                out.append(run_view(reader, path))
        except StorageError:
            continue  # a file being replaced (resume) shows up again on the next call
    return out


@router.get("/{run_id}", response_model=RunStatus, summary="Status of one run")
def get_run(storage: Annotated[Hdf5Reader, Depends(run_storage)],
            path: Annotated[Path, Depends(run_path)]) -> dict[str, Any]:
    return run_view(storage, path)
