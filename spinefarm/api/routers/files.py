"""GET /runs/{run_id}/file: the HDF5 file as a consistent snapshot, also while the run writes."""

from __future__ import annotations

import io
import os
import tempfile
from pathlib import Path
from typing import Annotated

from fastapi import APIRouter, Depends
from fastapi.responses import FileResponse, Response
from starlette.background import BackgroundTask

from spinefarm.api.deps import run_path, run_storage
from spinefarm.storage.export import write_csv
from spinefarm.storage.hdf5_reader import Hdf5Reader, snapshot

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


@router.get("/trials.csv", summary="Every trial as CSV (parameters in named columns)", response_class=Response,
            responses={200: {"content": {"text/csv": {}}, "description": "one row per trial, a header row first"}})
def csv_file(storage: Annotated[Hdf5Reader, Depends(run_storage)]) -> Response:
    buf = io.StringIO()
    write_csv(storage, buf)
    name = f"{storage.run_meta().run_id}.csv"
    return Response(buf.getvalue(), media_type="text/csv",
                    headers={"Content-Disposition": f'attachment; filename="{name}"'})
