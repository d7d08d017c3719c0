from __future__ import annotations

import time

import pytest

from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.settings import RunSettings
from spinefarm.protocol.states import TrialStatus
from spinefarm.storage.hdf5 import Hdf5Storage
from spinefarm.storage.memory import InMemoryStorage
from spinefarm.storage.schema import RunMeta


def make_meta(run_id: str = "run-a", n_params: int = 3, budget: int = 100) -> RunMeta:
    names = tuple(f"p{i}" for i in range(n_params))
    return RunMeta(
        run_id=run_id,
        morphology="sphere:3",
        controller=None,
        param_names=names,
        param_lows=(-1.0,) * n_params,
        param_highs=(1.0,) * n_params,
        param_units=("cm",) * n_params,
        objective="distance",
        seed=7,
        trials_budget=budget,
        sampler={"kind": "RandomSampler", "seed": 7},
        software_version="test",
        created_at_unix_s=time.time(),
        config_hash="abcd1234",
        settings=RunSettings(lease_s=3.0),
        run={"morphology_spec": {"nodes": [1, 2]}, "trial_config": {"duration_s": 0.5}},
    )


def result(
    trial_id: int, distance_m: float, *, status: TrialStatus = TrialStatus.COMPLETE, seed: int = 0, reason: str = ""
) -> TrialResult:
    return TrialResult(
        status,
        reason,
        distance_m,
        100 * distance_m,
        2.0,
        3.0,
        4.0,
        5.0,
        0.25,
        1.5,
        seed,
        trial_id=trial_id,
        worker_id="w-1",
    )


@pytest.fixture(params=["memory", "hdf5"])
def storage(request, tmp_path):
    if request.param == "memory":
        s = InMemoryStorage()
        s.create_run(make_meta())
    else:
        s = Hdf5Storage.create(tmp_path / "run.h5", make_meta())
    yield s
    s.close()
