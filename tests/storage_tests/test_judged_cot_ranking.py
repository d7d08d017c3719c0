"""A COT objective ranks a judged set by the judge's COT too (its evaluation row), on a real run file."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from spinefarm.storage.evaluations import row_of
from spinefarm.storage.hdf5 import Hdf5Storage
from spinefarm.storage.memory import InMemoryStorage
from tests.storage_tests.conftest import make_meta, result

# (trial, screen distance m, judged distance m or None, the judge's COT or None): every screen COT is 1,
# every trial 5 s. cot_distance = distance / (1 + COT):
#   screen: 0 -> 1.0/2 = 0.5, 1 -> 0.9/2 = 0.45, 2 -> 0.8/2 = 0.4, 3 -> 0.6/2 = 0.3
#   judged: 0 -> 1.0/(1+4) = 0.2, 1 -> 0.9/(1+0.5) = 0.6, 2 not judged 0.4, 3 judged with no judge's row: 0.3
# pareto = speed / (1 + COT), the speeds 20 x the distances: the same order.
SETS = [(0, 1.0, 1.0, 4.0), (1, 0.9, 0.9, 0.5), (2, 0.8, None, None), (3, 0.6, 0.6, None)]
JUDGED_ORDER = [1, 2, 3, 0]


def _write(s, objective: str) -> None:
    for tid, d, judged_m, judge_cot in SETS:
        s.add_trial(tid, np.full(3, 0.1 * tid), np.full(3, 0.1 * tid), "monte_carlo", -1, 100 + tid)
        screen = dataclasses.replace(result(tid, d), cot=1.0, speed_cm_s=20 * d)
        s.finish_trial(tid, screen, (d if objective == "cot_distance" else 20 * d) / 2.0)
        if judged_m is None:
            continue
        if judge_cot is not None:  # the judge's row comes first, as the ladder stores it
            s.add_evaluation(row_of(tid, "judge", dataclasses.replace(result(tid, judged_m), cot=judge_cot),
                                    "bullet", 2.5e-4, "w-2"))
        s.set_verification(tid, "judged", judged_m, ratio=1.0)


@pytest.mark.parametrize("objective", ["cot_distance", "pareto"])
def test_a_cot_objective_ranks_a_judged_set_by_the_judges_cot(objective, tmp_path):
    meta = dataclasses.replace(make_meta("run-c"), objective=objective)
    s = Hdf5Storage.create(tmp_path / "c.h5", meta)
    _write(s, objective)
    s.close()
    stored = Hdf5Storage.open_read(tmp_path / "c.h5")
    try:
        assert stored.best_ids(4) == JUDGED_ORDER
    finally:
        stored.close()
    memory = InMemoryStorage()
    memory.create_run(meta)
    _write(memory, objective)
    assert memory.best_ids(4) == JUDGED_ORDER


def test_a_distance_objective_still_ranks_by_the_judged_distance_alone(tmp_path):
    s = Hdf5Storage.create(tmp_path / "d.h5", make_meta("run-d"))
    _write(s, "cot_distance")  # objective "distance": its stored objective is ignored for judged sets
    assert s.best_ids(4)[:2] == [0, 1]  # judged 1.0 m and 0.9 m, whatever their COT
    s.close()
