"""A screened set ranks by its screen value times the screen's bias the judge measured (storage.ranking.screen_bias:
one over the median screen-to-judge ratio of three or more judged bests that moved 10 cm or more), so the judge
does not walk down a converged search's plateau of near-copies one by one. Every expected order below is worked
out by hand from the distances the test writes; the files are real run files (writer, resumed writer, reader)."""

from __future__ import annotations

import numpy as np

from spinefarm.coordinator.ladder.checks import Checks
from spinefarm.storage.hdf5 import Hdf5Storage
from spinefarm.storage.hdf5_reader import Hdf5Reader
from tests.coordinator_tests.test_best_judged import _robot_meta
from tests.storage_tests.conftest import result


def _add(storage: Hdf5Storage, tid: int, screen_m: float) -> None:
    storage.add_trial(tid, np.full(3, 0.5), np.zeros(3), "monte_carlo", -1, tid)
    storage.finish_trial(tid, result(tid, screen_m), screen_m)


def _judge(storage: Hdf5Storage, book: Checks, judged_m: dict[int, float]) -> None:
    for tid, d in judged_m.items():
        storage.set_verification(tid, "pending")
        book.settle_judge(tid, result(tid, d))


def _run(path, screens_m: list[float]) -> tuple[Hdf5Storage, Checks]:
    meta = _robot_meta("tetraspine")
    storage = Hdf5Storage.create(path, meta)
    for tid, d in enumerate(screens_m):
        _add(storage, tid, d)
    return storage, Checks(storage, meta.settings, None, 7, judged=True)


def test_three_judged_bests_discount_the_screen_by_their_median_ratio(tmp_path):
    # screen / judge ratios 3.50/3.33 = 1.0511, 3.40/3.20 = 1.0625, 3.30/3.15 = 1.0476: median 1.0511, so an
    # unjudged screen counts 1/1.0511 = 0.9514 of itself: 3.48 m -> 3.311 m (below the judged 3.33 m), 3.52 m
    # -> 3.349 m (above it)
    storage, book = _run(tmp_path / "r.h5", [3.50, 3.40, 3.30])
    _judge(storage, book, {0: 3.33, 1: 3.20, 2: 3.15})
    _add(storage, 3, 3.48)
    assert storage.best_ids(4) == [0, 3, 1, 2]
    _add(storage, 4, 3.52)
    assert storage.best_ids(5) == [4, 0, 3, 1, 2]
    assert book.judge_due(0, search_over=True)[0] is not None and storage.trial(4).verification == "pending"
    storage.close()
    with Hdf5Reader(tmp_path / "r.h5") as reader:   # the API's reader ranks as the writer does
        assert reader.best_ids(5) == [4, 0, 3, 1, 2]
    resumed = Hdf5Storage.resume(tmp_path / "r.h5")
    assert resumed.best_ids(5) == [4, 0, 3, 1, 2]
    resumed.close()


def test_two_judged_bests_or_bests_that_barely_moved_leave_the_screen_as_it_is(tmp_path):
    storage, book = _run(tmp_path / "r.h5", [3.50, 3.40, 0.08, 3.48])
    # two moved bests (ratios 1.05, 1.06) and one that moved 8 cm at most (ratio 0.08/0.02 = 4): no bias, so the
    # screen's 3.48 m outranks the judged 3.33 m; with the 8 cm set counted the median would be 1.06 and
    # 3.48 m would count 3.28 m, below it
    _judge(storage, book, {0: 3.33, 1: 3.20, 2: 0.02})
    assert storage.best_ids(3) == [3, 0, 1]
    storage.close()


def test_the_judge_stops_walking_down_a_plateau(tmp_path):
    # 40 near-copies screened 3.5600 .. 3.5561 m; the judge finds each 1.06, 1.04, 1.05, 1.06, ... times shorter.
    # Before three ratios the screen counts as it is, so the first three bests are judged (3.3585, 3.4230 and
    # 3.3903 m); then the bias is 1/1.05 and the next near-copy counts 3.5597/1.05 = 3.3902 m, below the judged
    # 3.4230 m of trial 1, which is the best: three judge runs, not forty
    screens = [3.5600 - 0.0001 * k for k in range(40)]
    storage, book = _run(tmp_path / "r.h5", screens)
    ratios = (1.06, 1.04, 1.05)
    runs = 0
    while book.judge_due(0, search_over=True)[0] is not None and runs < 40:
        tid = storage.best_ids(1)[0]
        book.settle_judge(tid, result(tid, screens[tid] / ratios[runs % 3]))
        runs += 1
    assert runs == 3
    assert storage.best_ids(1) == [1]
    assert abs(storage.trial(1).verify_distance_m - 3.5599 / 1.04) < 1e-12
    storage.close()


def test_the_bias_is_the_last_three_judged_bests_not_a_search_s_first_ones(tmp_path):
    # a search's first bests moved tens of centimetres and the screen read them 2.6 and 1.4 times the judge's
    # (0.587 / 0.2257, 0.64 / 0.4571: the paper-size search's first two); the last three read 1.05, 1.06 and
    # 1.04 (3.50 / 3.3333, 3.40 / 3.2075, 3.30 / 3.1731). The median of the last three, 1.05, makes a 3.58 m
    # screen count 3.58 / 1.05 = 3.4095 m, above the judged 3.3333 m: it ranks first and is the judge's next.
    # (The median of all five, 1.06, would make it 3.3774 m, still above; with a third early ratio of 1.9 the
    # median of all six would be 1.4 and the 3.58 m set would count 2.557 m, never judged.)
    screens = [0.587, 0.64, 0.70, 3.50, 3.40, 3.30, 3.58]
    storage, book = _run(tmp_path / "r.h5", screens)
    _judge(storage, book, {0: 0.587 / 2.6, 1: 0.64 / 1.4, 2: 0.70 / 1.9, 3: 3.50 / 1.05, 4: 3.40 / 1.06,
                           5: 3.30 / 1.04})
    assert storage.best_ids(3) == [6, 3, 4]
    assert book.judge_due(0, search_over=True)[0] is not None and storage.trial(6).verification == "pending"
    storage.close()
    with Hdf5Reader(tmp_path / "r.h5") as reader:
        assert reader.best_ids(3) == [6, 3, 4]
