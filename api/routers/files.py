"""GET /runs/{run_id}/file: the HDF5 file as a consistent snapshot, also while the run writes."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Annotated

from fastapi import APIRouter, Depends
from fastapi.responses import FileResponse
from starlette.background import BackgroundTask

from api.deps import run_path
from storage.hdf5 import snapshot

router = APIRouter(prefix="/runs/{run_id}", tags=["files"])


@router.get("/file", response_class=FileResponse, summary="Download the run's HDF5 file (snapshot)")
def download(path: Annotated[Path, Depends(run_path)]) -> FileResponse:
    fd, tmp = tempfile.mkstemp(suffix=".h5", prefix="spinefarm-snapshot-")
    os.close(fd)
    try:
        snapshot(path, tmp)
    except BaseException:
        os.unlink(tmp)
        raise
    return FileResponse(tmp, media_type="application/x-hdf5", filename=path.name,
                        background=BackgroundTask(os.unlink, tmp))
