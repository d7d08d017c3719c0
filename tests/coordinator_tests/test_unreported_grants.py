"""A worker that never runs the trials it is granted (its grants do not reach it, or it cannot fetch the run's config)
beside a healthy one: after scheduler.MAX_UNREPORTED asks its trials go to the healthy worker and the search ends.

Real Zenoh over TCP on loopback, the real coordinator service, the real worker in-process, and bench/fault_witness.py's
protocol worker with the fault "drop-grants" in its own process."""

from __future__ import annotations

import logging
import threading
import time

import numpy as np
import pytest

from bench.fault_witness import witness
from spinefarm.coordinator.scheduler import MAX_UNREPORTED
from spinefarm.coordinator.service import CoordinatorService
from spinefarm.worker.service.zenoh_worker import WorkerService, ZenohAccess
from tests.coordinator_tests.helpers import free_endpoint, sphere_core, wait_for

pytestmark = pytest.mark.integration
TRIALS = 12


def test_trials_a_worker_drops_are_run_by_a_healthy_worker_and_the_search_ends(tmp_path, caplog):
    caplog.set_level(logging.WARNING, logger="spinefarm.coordinator")
    endpoint = free_endpoint()
    core, storage, _ = sphere_core(trials=TRIALS, lease_s=2.0, clock=time.monotonic, morphology="sphere:2",
                                   duration_s=0.05)
    service = CoordinatorService(core, storage, listen=[endpoint]).start()
    dropper = witness(endpoint, core.run_id, "dropper", tmp_path / "dropper.jsonl", fault="drop-grants")
    healthy = WorkerService(ZenohAccess([endpoint]), run_id=core.run_id, worker_id="healthy", exit_when_done=True)
    thread = threading.Thread(target=healthy.run, daemon=True)
    try:
        # the dropper holds a grant before the healthy worker starts: trials it dropped must reach the other
        wait_for(lambda: "dropper" in core.scheduler.workers and core.scheduler.workers["dropper"].leases,
                 timeout_s=60, what="a grant to the dropping worker")
        thread.start()
        # without the bar the dropper is granted its trials again for ever and the search never ends
        assert service.wait_done(60), f"search stuck at {storage.counts()}"
        thread.join(20)
        assert not thread.is_alive()
    finally:
        healthy.stop.set()
        dropper.kill()
        dropper.wait()
        service.close()
    cols = storage.columns()
    assert storage.counts() == {"waiting": 0, "complete": TRIALS, "failed": 0}
    assert set(cols["worker_id"][np.flatnonzero(cols["status"] == b"complete")]) == {b"healthy"}
    lines = [r.getMessage() for r in caplog.records if "dropper" in r.getMessage()]
    barred = [ln for ln in lines if "times in a row" in ln]
    again = [ln for ln in lines if "a grant it never got" in ln]
    assert len(barred) == 1 and f"{MAX_UNREPORTED} times in a row" in barred[0], lines
    assert len(again) == MAX_UNREPORTED - 1, lines   # issued again to it before the bar, then no more
