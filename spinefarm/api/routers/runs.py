"""GET /runs and /runs/{run_id}: runs and their status."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Annotated, Any

from fastapi import APIRouter, Depends, Query

from spinefarm.api.analysis import analysis_view, columns_view
from spinefarm.api.contour import CONTOUR_VALUES, contour_view
from spinefarm.api.deps import registry, run_path, run_storage
from spinefarm.api.registry import RunRegistry
from spinefarm.api.schemas import RunStatus
from spinefarm.api.views import run_view
from spinefarm.protocol.errors import SpinefarmError, StorageError
from spinefarm.storage.codesign_coverage import run_coverage
from spinefarm.storage.hdf5_reader import Hdf5Reader

router = APIRouter(prefix="/runs", tags=["runs"])
files_router = APIRouter(tags=["runs"])
log = logging.getLogger("spinefarm.api")


@files_router.get("/damaged-files", summary="Run files the API leaves out (damaged, not run files, or not read yet "
                  "on a busy machine) or cannot show now, and why")
def damaged_files(reg: Annotated[RunRegistry, Depends(registry)]) -> list[dict[str, str]]:
    reg.runs()  # probe what is new since the last call
    return [{"file": str(path), "reason": why} for path, why in reg.damaged()]


def _status(path: Path) -> dict[str, Any]:
    """A run's status entry, checked as /runs serves it: a file that cannot give one fails here, alone."""
    try:
        with Hdf5Reader(path) as reader:
            return RunStatus.model_validate(run_view(reader, path)).model_dump()
    except SpinefarmError:
        raise
    except Exception as exc:  # a file its read found whole, holding what no run file holds: a 409, not a 500
        raise StorageError(f"cannot show run file {path}: {type(exc).__name__}: {str(exc).splitlines()[0][:200]}",
                           expected="a run file as spinefarm writes it") from exc


@router.get("", response_model=list[RunStatus], summary="Every run and its status")
def list_runs(reg: Annotated[RunRegistry, Depends(registry)]) -> list[dict[str, Any]]:
    out = []
    for path in reg.runs().values():
        try:
            out.append(reg.view(path, lambda path=path: _status(path)))
        except Exception as exc:
            # one run that cannot be shown (a file being replaced, or tampered with in a way its read did not
            # catch) never takes down the list: it is named in /damaged-files until it can be shown again
            log.warning("cannot show %s now: %s", path, str(exc).splitlines()[0][:300])
    return out


@router.get("/{run_id}", response_model=RunStatus, summary="Status of one run")
def get_run(reg: Annotated[RunRegistry, Depends(registry)],
            path: Annotated[Path, Depends(run_path)]) -> dict[str, Any]:
    return reg.view(path, lambda: _status(path))


@router.get("/{run_id}/columns", summary="Every trial as columns (row i = trial i), parameters by name")
def get_columns(storage: Annotated[Hdf5Reader, Depends(run_storage)],
                params: bool = Query(True, description="include the parameter columns")) -> dict[str, Any]:
    return columns_view(storage, with_params=params)


@router.get("/{run_id}/analysis", summary="Pareto front (distance vs COT), parameter importance, failures")
def get_analysis(storage: Annotated[Hdf5Reader, Depends(run_storage)]) -> dict[str, Any]:
    return analysis_view(storage)


@router.get("/{run_id}/meta", summary="The run's configuration: morphology, controller, trial config, sampler")
def get_meta(storage: Annotated[Hdf5Reader, Depends(run_storage)]) -> dict[str, Any]:
    m = storage.run_meta()
    return {"run_id": m.run_id, "morphology": m.morphology, "controller": m.controller, "objective": m.objective,
            "seed": m.seed, "trials_budget": m.trials_budget, "sampler": m.sampler, "trial_config": m.trial_config,
            "param_names": list(m.param_names), "param_units": list(m.param_units),
            "param_lows": list(m.param_lows), "param_highs": list(m.param_highs),
            "software_version": m.software_version, "created_at_unix_s": m.created_at_unix_s,
            "physical": bool(m.morphology_spec), "settings": m.settings.to_dict(),
            "robust": m.run.get("robust") or {},
            # each time a coordinator created or resumed the run, oldest first: the last one serves it
            "instances": list(m.instances),
            # how `search --engine auto` chose the tier, with its calibration's figures (None: engine given)
            "engine_choice": None if m.settings.engine_choice is None else m.settings.engine_choice.to_dict(),
            # a co-designed run: the calibration covers the base body; the judge's ratios on sampled bodies
            "codesign": run_coverage(m, storage.columns()) if m.run.get("body") else None}


@router.get("/{run_id}/contour",
            summary="One score over two parameters on a grid (a kernel-weighted mean of the complete trials) and "
                    "the trials it comes from")
def get_contour(storage: Annotated[Hdf5Reader, Depends(run_storage)],
                x: Annotated[str, Query(max_length=200, description="the parameter along x")],
                y: Annotated[str, Query(max_length=200, description="the parameter along y")],
                grid: Annotated[int, Query(description="cells along each axis, 2 to 200")] = 40,
                value: Annotated[str, Query(description="the score drawn: " + ", ".join(CONTOUR_VALUES))] = "objective",
                rung: Annotated[int, Query(description="the rung of a multi-fidelity run whose trials are drawn "
                                                       "(0, the default: the first, every parameter set once)")] = 0,
                ) -> dict[str, Any]:
    return contour_view(storage, x, y, grid, value, rung)
