"""No exploited physics: a new best is re-simulated at a finer step before it counts."""

from __future__ import annotations

import dataclasses
import os

import numpy as np
from spinefarm.coordinator.problem import build_run_config
from spinefarm.coordinator.setup import SearchSettings, new_run
from spinefarm.coordinator.verifier import JUDGE_NICENESS, VerifyPolicy
from spinefarm.protocol.messages import (
    ResultAck,
    ResultSubmission,
    SubmittedResult,
    WorkGrant,
    WorkRequest,
    decode_message,
)
from spinefarm.protocol.messages import encode_message as enc
from spinefarm.storage.hdf5 import Hdf5Storage
from spinefarm.worker.trial import TrialConfig, run_trial

from tests.coordinator_tests.helpers import FakeClock


def _run_grant(core, config, n: int) -> list[SubmittedResult]:
    """Ask for n trials as worker w1 and run them: the submissions, not yet sent."""
    grant = decode_message(core.handle_work(enc(WorkRequest("w1", n))), WorkGrant)
    out = []
    for a in grant.assignments:
        r = run_trial(config.morphology, np.array(a.params_unit), TrialConfig.from_dict(config.trial_config), a.seed)
        out.append(SubmittedResult(a.lease_id, dataclasses.replace(r, trial_id=a.trial_id, worker_id="w1")))
    return out


def test_a_bogus_best_is_not_reproduced_and_the_next_best_is_checked(tmp_path):
    config = build_run_config("verify-run", "tetraspine-ntrt", seed=1, duration_s=1.0)
    settings = SearchSettings(trials=2, startup_trials=2, verify=VerifyPolicy(tolerance=0.2))
    core, storage = new_run(config, settings, tmp_path / "run.h5", FakeClock())
    try:
        real, honest = _run_grant(core, config, 2)
        # trial 0 claims 5 m, as an exploded simulation would; trial 1 reports what it really did
        bogus = dataclasses.replace(real.result, distance_m=5.0, ntrt_distance_cm=500.0)
        items = (dataclasses.replace(real, result=bogus), honest)
        decode_message(core.handle_results(enc(ResultSubmission("w1", items))), ResultAck)
        assert storage.columns()["verification"][0] == b"pending"
        assert core.finish_verifications(timeout_s=120.0)
        cols = storage.columns()
        assert cols["verification"][0] == b"not_reproduced"
        assert 0.0 < cols["verify_distance_m"][0] < 1.0 and b"finer step" in cols["verify_reason"][0]
        assert cols["verification"][1] == b"holds"  # checked in turn once trial 0 fell out
        assert storage.best_ids(2) == [1]  # the bogus trial never counts as best again
        assert cols["distance_m"][0] == 5.0  # both figures are stored
    finally:
        core.verifier.close()
        storage.close()
    reread = Hdf5Storage.open_read(tmp_path / "run.h5")
    assert [t.trial_id for t in reread.best(2)] == [1] and reread.trial(0).verification == "not_reproduced"


def test_test_objectives_and_disabled_policies_have_no_verifier(tmp_path):
    sphere = build_run_config("s", "sphere:3")
    core, _ = new_run(sphere, SearchSettings(trials=2), None, FakeClock())
    assert core.verifier is None
    config = build_run_config("v", "tetraspine-ntrt", duration_s=0.1)
    core, _storage = new_run(config, SearchSettings(trials=2, verify=VerifyPolicy(enabled=False)), None, FakeClock())
    assert core.verifier is None


def test_the_judge_runs_below_the_workers_priority(tmp_path):
    config = build_run_config("v", "tetraspine-ntrt", duration_s=0.05)
    core, storage = new_run(config, SearchSettings(trials=1), tmp_path / "run.h5", FakeClock())
    try:
        core.verifier.submit(0, [0.5] * len(config.param_space), 1, 0.0)
        [(tid, verdict)] = core.verifier.collect(wait_s=120.0)
        assert tid == 0 and "holds" in verdict
        [proc] = core.verifier._pool._processes.values()
        assert os.getpriority(os.PRIO_PROCESS, proc.pid) >= JUDGE_NICENESS
    finally:
        core.verifier.close()
        storage.close()


def test_once_the_search_is_over_a_check_of_an_overtaken_best_is_stopped(tmp_path):
    """The check of an earlier best is still running when a better result arrives and the budget is done:
    it is stopped (its trial left unchecked) so the best's own check starts at once."""
    import time

    config = build_run_config("overtaken", "tetraspine-ntrt", seed=3, duration_s=1.0)
    settings = SearchSettings(trials=2, startup_trials=2, verify=VerifyPolicy(refine=16))
    core, storage = new_run(config, settings, tmp_path / "run.h5", FakeClock())
    try:
        first, better = sorted(_run_grant(core, config, 2), key=lambda s: s.result.distance_m)
        decode_message(core.handle_results(enc(ResultSubmission("w1", (first,)))), ResultAck)
        earlier = first.result.trial_id
        deadline = time.monotonic() + 60.0
        while not core.verifier._futures[earlier].running():  # the earlier best's check has started
            assert time.monotonic() < deadline
            time.sleep(0.05)
        decode_message(core.handle_results(enc(ResultSubmission("w1", (better,)))), ResultAck)
        assert core.done
        assert core.finish_verifications(timeout_s=120.0)
        cols = storage.columns()
        assert cols["verification"][better.result.trial_id] == b"holds"
        assert cols["verification"][earlier] == b""  # stopped, not judged
    finally:
        core.verifier.close()
        storage.close()
