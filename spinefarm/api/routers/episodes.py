"""GET /runs/{run_id}/trials/{trial_id}/episodes: a robust trial's episodes and their spread."""

from __future__ import annotations

import math
from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, Depends, Path
from pydantic import BaseModel

from spinefarm.api.deps import run_storage
from spinefarm.api.errors import NotFound
from spinefarm.storage.episodes import EPISODE_COLUMNS
from spinefarm.storage.hdf5_reader import Hdf5Reader

router = APIRouter(prefix="/runs/{run_id}", tags=["trials"])


class Spread(BaseModel):
    """Of the complete episodes: median, quartiles (numpy's linear percentiles), extremes, mean."""

    median: float | None
    q25: float | None
    q75: float | None
    min: float | None
    max: float | None
    mean: float | None


class Episodes(BaseModel):
    trial_id: int
    robust: dict[str, Any]   # the run's robust settings (episodes, randomize, statistic); {} for a plain run
    episodes: list[dict[str, Any]]
    spread: dict[str, Spread]  # speed_cm_s, distance_m, cot


def spread(values: np.ndarray) -> dict[str, float | None]:
    v = values[np.isfinite(values)]
    if v.size == 0:
        return dict.fromkeys(("median", "q25", "q75", "min", "max", "mean"))
    q25, q50, q75 = (float(x) for x in np.percentile(v, [25, 50, 75]))
    return {"median": q50, "q25": q25, "q75": q75, "min": float(v.min()), "max": float(v.max()),
            "mean": float(v.mean())}


def _value(v: Any) -> Any:
    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    v = v.item() if hasattr(v, "item") else v
    return None if isinstance(v, float) and not math.isfinite(v) else v


@router.get("/trials/{trial_id}/episodes", response_model=Episodes,
            summary="A robust trial's episodes (each its own randomised world) and their spread")
def episodes(storage: Annotated[Hdf5Reader, Depends(run_storage)],
             trial_id: Annotated[int, Path(ge=0, le=2**62, description="trial number")]) -> dict[str, Any]:
    n = storage.n_trials()
    if trial_id >= n:
        raise NotFound("no such trial", received=trial_id, expected=f"0 <= trial_id < {n}")
    cols = storage.episodes(trial_id)
    rows = [{c.name: _value(cols[c.name][i]) for c in EPISODE_COLUMNS} for i in range(len(cols["trial_id"]))]
    ok = cols["status"] == b"complete"
    return {"trial_id": trial_id, "robust": storage.run_meta().run.get("robust") or {}, "episodes": rows,
            "spread": {k: spread(np.asarray(cols[k][ok], dtype=float)) for k in ("speed_cm_s", "distance_m", "cot")}}
