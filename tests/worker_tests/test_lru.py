"""worker.trial.lru: the one least-recently-used dict the worker's kept ends share, checked by hand."""

from __future__ import annotations

import pytest

from spinefarm.worker.trial.lru import LRU


def test_a_touched_value_outlives_an_untouched_older_one():
    kept: LRU[str, int] = LRU(2, "probes")
    kept.put("first", 1)
    kept.put("second", 2)
    kept.put("third", 3)                       # over size 2: "first", the least recently used, goes
    assert len(kept) == 2 and kept.get("first") is None
    kept.put("first", 10)                      # back in; "second" is now the oldest
    assert kept.get("first") == 10             # touched: "third" is now the oldest
    kept.put("fourth", 4)
    assert kept.get("third") is None and kept.get("second") is None
    assert kept.get("first") == 10 and kept.get("fourth") == 4


def test_touching_the_first_of_three_evicts_the_second_at_the_fourth():
    kept: LRU[str, str] = LRU(2, "probes")
    kept.put("a", "A")
    kept.put("b", "B")
    assert kept.get("a") == "A"                # touch the first
    kept.put("c", "C")                         # "b" is gone, not "a"
    assert kept.get("b") is None and kept.get("a") == "A" and kept.get("c") == "C"


def test_hits_and_misses_and_an_unusable_value_is_a_miss_left_untouched():
    kept: LRU[str, int] = LRU(2, "probes")
    kept.put("x", 5)
    kept.put("y", 7)
    assert kept.get("x", lambda v: v > 6) is None      # kept but not usable: a miss, "x" not touched
    kept.put("z", 9)                                   # so "x" is still the oldest and goes
    assert kept.get("x") is None and kept.get("y", lambda v: v > 6) == 7
    assert (kept.hits, kept.misses) == (1, 2)


def test_size_zero_keeps_nothing():
    kept: LRU[str, int] = LRU(0, "probes")
    kept.put("a", 1)
    assert len(kept) == 0 and kept.get("a") is None


def test_a_smaller_size_trims_the_oldest_at_the_next_put():
    kept: LRU[str, int] = LRU(3, "probes")
    for i, key in enumerate("abc"):
        kept.put(key, i)
    kept.size = 1
    kept.put("d", 3)
    assert len(kept) == 1 and kept.get("d") == 3 and kept.get("c") is None


@pytest.mark.parametrize("make", [lambda: LRU(-3, "probes"), lambda: setattr(LRU(1, "probes"), "size", -3)])
def test_a_negative_size_is_refused_in_one_line_naming_it(make):
    with pytest.raises(ValueError) as refused:
        make()
    assert str(refused.value) == "size of the probes is negative: received -3, expected >= 0"
