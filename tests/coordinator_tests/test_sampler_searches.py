"""CMA-ES and TPE searches end to end: a coordinator and two workers over Zenoh on loopback, a real run file."""

from __future__ import annotations

import numpy as np
import pytest

from spinefarm.storage import pareto
from spinefarm.storage.hdf5 import Hdf5Storage
from tests.coordinator_tests.helpers import free_endpoint
from tests.coordinator_tests.procs import coordinator, stop, worker

pytestmark = pytest.mark.integration


@pytest.mark.parametrize(("sampler", "objective"), [("cmaes", "distance"), ("tpe", "distance"), ("tpe", "pareto")])
def test_search_with_a_model_based_sampler_over_zenoh(tmp_path, sampler, objective):
    ep, out, budget = free_endpoint(), tmp_path / "run.h5", 100
    coord = coordinator(ep, out, "sphere:4", "--trials", str(budget), "--duration", "0.005", "--run-id", sampler,
                        "--sampler", sampler, "--seed", "4", "--objective", objective)
    workers = [worker(ep, sampler, f"w{i}", batch=2) for i in range(2)]
    try:
        assert coord.wait(120) == 0
        for w in workers:
            assert w.wait(20) == 0
    finally:
        stop(coord, *workers)
    s = Hdf5Storage.open_read(out)
    cols = s.columns()
    assert cols["trial_id"].tolist() == list(range(budget))
    assert set(cols["status"].tolist()) == {b"complete"}
    assert set(cols["phase"].tolist()) == {sampler.encode()}
    assert s.run_meta().sampler["name"] == sampler and s.run_meta().objective == objective
    assert np.array_equal(cols["pareto_front"] == 1, pareto.front_mask(cols["status"], cols["speed_cm_s"], cols["cot"]))
    if objective == "distance":  # the sphere's top is 4 (x = 0.3); the sampler closes in on it
        gap = 4.0 - cols["distance_m"]
        assert gap.min() < 0.15 < float(np.median(gap[:10]))
    else:  # speed and COT: the front spreads over more than one trial, and the multi-objective TPE ran
        assert s.run_meta().sampler["multi_objective"] and int(cols["pareto_front"].sum()) >= 2
    s.close()
