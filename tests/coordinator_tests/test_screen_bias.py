"""A screened set ranks by its screen value times the screen's bias the judge measured (storage.ranking.screen_bias:
one over the smallest screen-to-judge ratio of the last three judged bests that moved 10 cm or more), so the judge
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


def test_three_judged_bests_discount_the_screen_by_their_closest_ratio(tmp_path):
    # screen / judge ratios 3.50/3.33 = 1.0511, 3.40/3.20 = 1.0625, 3.30/3.15 = 1.0476: the smallest 1.0476, so
    # an unjudged screen counts 1/1.0476 = 0.9545 of itself: 3.48 m -> 3.3218 m (below the judged 3.33 m),
    # 3.52 m -> 3.3600 m (above it)
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
    # two moved bests (ratios 1.0511, 1.0625) and one that moved 8 cm at most (ratio 0.08/0.02 = 4): no bias, so
    # the screen's 3.48 m outranks the judged 3.33 m; with the 8 cm set counted the smallest would be 1.0511 and
    # 3.48 m would count 3.3108 m, below it
    _judge(storage, book, {0: 3.33, 1: 3.20, 2: 0.02})
    assert storage.best_ids(3) == [3, 0, 1]
    storage.close()


def test_a_best_that_moved_exactly_10_cm_counts(tmp_path):
    # the drift rule's population: bests that moved 10 cm or more. A third best screened 0.10 m and judged
    # 0.05 m (ratio 2) makes three ratios (1.0511, 1.0625, 2): the smallest, 1.0511, makes 3.48 m count
    # 3.3108 m, below the judged 3.33 m
    storage, book = _run(tmp_path / "r.h5", [3.50, 3.40, 0.10, 3.48])
    _judge(storage, book, {0: 3.33, 1: 3.20, 2: 0.05})
    assert storage.best_ids(3) == [0, 3, 1]
    storage.close()


def test_the_judge_stops_walking_down_a_plateau(tmp_path):
    # 40 near-copies screened 3.5600 .. 3.5561 m; the judge finds each 1.06, 1.04, 1.05, 1.06, ... times shorter.
    # Before three ratios the screen counts as it is, so the first three bests are judged (3.3585, 3.4230 and
    # 3.3903 m); then the bias is 1/1.04 and the next near-copy counts 3.5597/1.04 = 3.42279 m, below the judged
    # 3.5599/1.04 = 3.42298 m of trial 1, which is the best: three judge runs, not forty
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


def test_at_a_search_s_start_its_first_bests_far_readings_do_not_keep_its_best_from_the_judge(tmp_path):
    # the paper-size search's first two judged bests read 2.6 and 1.4 times the judge's (0.587 m, 0.64 m
    # screened), the third, near the top, 1.05 (3.40 m -> 3.2381 m). By the closest of the three a 3.58 m screen
    # counts 3.58/1.05 = 3.4095 m, above the judged 3.2381 m: it is the judge's next. (By their median, 1.4, it
    # would count 2.557 m and never be judged, nor any set after it.)
    storage, book = _run(tmp_path / "r.h5", [0.587, 0.64, 3.40, 3.58])
    _judge(storage, book, {0: 0.587 / 2.6, 1: 0.64 / 1.4, 2: 3.40 / 1.05})
    assert storage.best_ids(2) == [3, 2]
    assert book.judge_due(0, search_over=True)[0] is not None and storage.trial(3).verification == "pending"
    storage.close()
    with Hdf5Reader(tmp_path / "r.h5") as reader:
        assert reader.best_ids(2) == [3, 2]


def test_the_bias_is_the_last_three_judged_bests_not_an_early_one(tmp_path):
    # an early best the screen read at half the judge's (0.20 m screened, 0.40 m judged: ratio 0.5), then three
    # near the top at 1.05, 1.06, 1.04 (3.50 / 3.3333, 3.45 / 3.2547, 3.30 / 3.1731). By the last three (1.04) a
    # 3.40 m screen counts 3.40/1.04 = 3.2692 m, below the judged 3.3333 m; counting the early 0.5 it would count
    # 6.80 m and outrank every judged set (and the judge would run set after set)
    storage, book = _run(tmp_path / "r.h5", [0.20, 3.50, 3.45, 3.30, 3.40])
    _judge(storage, book, {0: 0.40, 1: 3.50 / 1.05, 2: 3.45 / 1.06, 3: 3.30 / 1.04})
    assert storage.best_ids(3) == [1, 4, 2]
    storage.close()
    with Hdf5Reader(tmp_path / "r.h5") as reader:
        assert reader.best_ids(3) == [1, 4, 2]
