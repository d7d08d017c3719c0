"""GET /runs/{run_id}/best, /runs/{run_id}/pareto, /runs/{run_id}/trials (a page of them) and
/runs/{run_id}/trials/{trial_id}."""

from __future__ import annotations

from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, Depends, Path, Query, Request
from fastapi.responses import FileResponse, JSONResponse

from spinefarm.api.deps import run_storage
from spinefarm.api.errors import NotFound
from spinefarm.api.schemas import Trial, TrialPage
from spinefarm.api.views import judged_cot_view, trial_view
from spinefarm.protocol.states import TrialStatus
from spinefarm.storage.hdf5_reader import Hdf5Reader
from spinefarm.storage.model_spread import model_spread
from spinefarm.storage.schema import TrialRecord

router = APIRouter(prefix="/runs/{run_id}", tags=["trials"])


@router.get("/best", response_model=list[Trial], summary="The k best complete trials, best first (with auditing on, "
            "only those another worker identity's audit agreed with; /runs shows a better one pending its audit)")
def best(storage: Annotated[Hdf5Reader, Depends(run_storage)],
         k: Annotated[int, Query(ge=1, le=1000, description="how many trials")] = 10) -> list[dict[str, Any]]:
    cols = storage.evaluations()
    return [{**trial_view(storage, rec), **judged_cot_view(rec, cols), "model_spread": model_spread(storage, rec, cols)}
            for rec in storage.reported_best(k)[0]]


@router.get("/pareto", response_model=list[Trial],
            summary="The Pareto front of speed (max) and COT (min) among complete trials, fastest first")
def pareto(storage: Annotated[Hdf5Reader, Depends(run_storage)]) -> list[dict[str, Any]]:
    return [trial_view(storage, rec) for rec in storage.records(storage.pareto_ids())]


@router.get("/trials", response_model=TrialPage, summary="A page of trials in id order, of one status or all")
def trials_page(storage: Annotated[Hdf5Reader, Depends(run_storage)],
                offset: Annotated[int, Query(ge=0, le=2**62, description="trials to skip")] = 0,
                limit: Annotated[int, Query(ge=1, le=1000, description="trials in the page")] = 100,
                status: Annotated[TrialStatus | None, Query(description="only trials of this status")] = None
                ) -> dict[str, Any]:
    ids = np.arange(storage.n_trials()) if status is None else np.flatnonzero(
        storage.columns()["status"] == status.stored)
    page = [trial_view(storage, rec) for rec in storage.records(ids[offset:offset + limit].tolist())]
    return {"run_id": storage.run_meta().run_id, "status": None if status is None else status.value,
            "total": int(ids.size), "offset": offset, "limit": limit, "trials": page}


@router.get("/trials/{trial_id}", response_model=Trial, summary="One trial")
def trial(storage: Annotated[Hdf5Reader, Depends(run_storage)],
          trial_id: Annotated[int, Path(ge=0, le=2**62, description="trial number")]) -> dict[str, Any]:
    rec = _record(storage, trial_id)
    cols = storage.evaluations()
    return {**trial_view(storage, rec), **judged_cot_view(rec, cols), "model_spread": model_spread(storage, rec, cols)}


TrialId = Annotated[int, Path(ge=0, le=2**62, description="trial number")]


def _record(storage: Hdf5Reader, trial_id: int) -> TrialRecord:
    n = storage.n_trials()
    if trial_id >= n:
        raise NotFound("no such trial", received=trial_id, expected=f"0 <= trial_id < {n}")
    return storage.trial(trial_id)


@router.get("/trials/{trial_id}/params.json", summary="The trial's parameters as a `spinefarm trial --params` file")
def params_file(storage: Annotated[Hdf5Reader, Depends(run_storage)], trial_id: TrialId) -> JSONResponse:
    rec = _record(storage, trial_id)
    meta = storage.run_meta()
    body = {"controller": meta.controller, "params": dict(zip(meta.param_names, rec.params, strict=True))}
    name = f"{meta.run_id}-trial-{trial_id}-params.json"
    return JSONResponse(body, headers={"Content-Disposition": f'attachment; filename="{name}"'})


@router.get("/trials/{trial_id}/picture.png", response_class=FileResponse,
            summary="The gait as a strip of keyframes, strings coloured by tension (rendered once, then cached)",
            responses={503: {"description": "this server has no simulator to draw with"}})
def picture(request: Request, storage: Annotated[Hdf5Reader, Depends(run_storage)],
            trial_id: TrialId) -> FileResponse:
    rec = _record(storage, trial_id)
    meta = storage.run_meta()
    storage.close()  # drawing can take a while: do not hold the run file open meanwhile
    path = request.app.state.pictures.picture(meta, rec)
    return FileResponse(path, media_type="image/png")


@router.get("/trials/{trial_id}/motion.json", response_class=FileResponse,
            summary="The trial's motion for the 3D view: body-frame geometry once, then poses, string tensions and "
                    "the centre of mass at 30 frames per second (re-simulated once, then cached)",
            responses={503: {"description": "this server has no simulator to re-simulate with"}})
def motion(request: Request, storage: Annotated[Hdf5Reader, Depends(run_storage)],
           trial_id: TrialId) -> FileResponse:
    rec = _record(storage, trial_id)
    meta = storage.run_meta()
    storage.close()  # re-simulating can take a while: do not hold the run file open meanwhile
    path = request.app.state.pictures.motion(meta, rec)
    return FileResponse(path, media_type="application/json")
