"""GET /runs/{run_id}/best, /runs/{run_id}/pareto and /runs/{run_id}/trials/{trial_id}."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, Path, Query

from api.deps import run_storage
from api.errors import NotFound
from api.schemas import Trial
from api.views import trial_view
from storage.hdf5_reader import Hdf5Reader

router = APIRouter(prefix="/runs/{run_id}", tags=["trials"])


@router.get("/best", response_model=list[Trial], summary="The k best complete trials, best first")
def best(storage: Annotated[Hdf5Reader, Depends(run_storage)],
         k: Annotated[int, Query(ge=1, le=1000, description="how many trials")] = 10) -> list[dict[str, Any]]:
    return [trial_view(storage, rec) for rec in storage.best(k)]


@router.get("/pareto", response_model=list[Trial],
            summary="The Pareto front of speed (max) and COT (min) among complete trials, fastest first")
def pareto(storage: Annotated[Hdf5Reader, Depends(run_storage)]) -> list[dict[str, Any]]:
    return [trial_view(storage, storage.trial(i)) for i in storage.pareto_ids()]


@router.get("/trials/{trial_id}", response_model=Trial, summary="One trial")
def trial(storage: Annotated[Hdf5Reader, Depends(run_storage)],
          trial_id: Annotated[int, Path(ge=0, le=2**62, description="trial number")]) -> dict[str, Any]:
    n = storage.n_trials()
    if trial_id >= n:
        raise NotFound("no such trial", received=trial_id, expected=f"0 <= trial_id < {n}")
    return trial_view(storage, storage.trial(trial_id))
