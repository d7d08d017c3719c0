"""Every storage keeps the same contract: dense ids, results stored once, best by objective."""

from __future__ import annotations

import numpy as np
import pytest

from spinefarm.protocol.errors import StorageError
from spinefarm.protocol.states import TrialStatus
from tests.storage_tests.conftest import result


def add(storage, n: int) -> None:
    for i in range(storage.n_trials(), storage.n_trials() + n):
        u = np.full(3, i / 100)
        storage.add_trial(i, u, 2 * u - 1, "monte_carlo", -1, 1000 + i)


def test_added_trials_wait_and_keep_their_vectors(storage):
    add(storage, 4)
    assert storage.n_trials() == 4
    assert storage.counts() == {"waiting": 4, "complete": 0, "failed": 0}
    rec = storage.trial(2)
    assert rec.params_unit == pytest.approx((0.02,) * 3)
    assert rec.params == pytest.approx((-0.96,) * 3)
    assert (rec.status, rec.phase, rec.parent, rec.seed) == ("waiting", "monte_carlo", -1, 1002)


def test_ids_must_be_dense(storage):
    add(storage, 2)
    with pytest.raises(StorageError, match="densely"):
        storage.add_trial(5, np.zeros(3), np.zeros(3), "monte_carlo", -1, 0)


def test_a_result_is_stored_once(storage):
    add(storage, 3)
    assert storage.finish_trial(1, result(1, 0.5), 0.5)
    assert not storage.finish_trial(1, result(1, 9.0), 9.0)
    rec = storage.trial(1)
    assert (rec.status, rec.distance_m, rec.objective, rec.worker_id) == ("complete", 0.5, 0.5, "w-1")
    assert rec.ntrt_distance_cm == 50.0 and rec.cot == 4.0 and rec.wall_time_s == 0.25


def test_failed_trials_keep_reason_and_are_never_best(storage):
    add(storage, 3)
    storage.finish_trial(0, result(0, 5.0, status=TrialStatus.FAILED, reason="diverged: speed"), 5.0)
    storage.finish_trial(1, result(1, 1.0), 1.0)
    assert storage.trial(0).reason == "diverged: speed"
    assert storage.best_ids(5) == [1]
    assert storage.counts() == {"waiting": 1, "complete": 1, "failed": 1}
    assert storage.waiting_ids() == [2]


def test_best_orders_by_objective_and_breaks_ties_by_id(storage):
    add(storage, 6)
    for tid, obj in [(0, 1.0), (1, 3.0), (2, 3.0), (3, float("nan")), (4, 2.0)]:
        storage.finish_trial(tid, result(tid, obj), obj)
    assert storage.best_ids(1) == [1]
    assert storage.best_ids(3) == [1, 2, 4]
    assert storage.best_ids(10) == [1, 2, 4, 0]
    assert [r.trial_id for r in storage.best(2)] == [1, 2]


def test_unknown_trial_is_a_storage_error(storage):
    add(storage, 1)
    with pytest.raises(StorageError, match="no such trial"):
        storage.trial(3)
    with pytest.raises(StorageError, match="no such trial"):
        storage.finish_trial(3, result(3, 1.0), 1.0)


def test_growth_beyond_initial_capacity(storage):
    add(storage, 2500)
    storage.finish_trial(2400, result(2400, 7.0), 7.0)
    storage.flush()
    assert storage.n_trials() == 2500
    assert storage.best_ids(1) == [2400]
    assert storage.trial(2499).seed == 3499
