"""A robust trial's figures (docs/robust.md's promise, worker.robust): the parts are the medians of the
episodes (not their mean), the statistics are worked by hand, and a drawn friction reaches the simulator."""

from __future__ import annotations

import dataclasses
import math

import pytest

from spinefarm.protocol.robust import EpisodeDraw, RobustSpec, statistic
from spinefarm.protocol.states import TrialStatus
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.worker.robust import combine, run_episodes
from spinefarm.worker.trial import TrialConfig, random_unit_params
from tests.storage_tests.conftest import result


def _episodes(distances_m, works_j, failed=()):
    out = []
    for k, (d, w) in enumerate(zip(distances_m, works_j, strict=True)):
        r = dataclasses.replace(result(-1, d), work_j=w, wall_time_s=1.0 + k)
        if k in failed:
            r = dataclasses.replace(r, status=TrialStatus.FAILED, reason="diverged: nan")
        out.append(r)
    return out, [EpisodeDraw(k, 100 + k) for k in range(len(out))]


def test_the_trial_is_the_median_of_three_distinct_episodes():
    # distances 1, 6, 2 m: median 2 (their mean would be 3); works 10, 40, 20 J: median 20 (mean 23.3)
    results, draws = _episodes([1.0, 6.0, 2.0], [10.0, 40.0, 20.0])
    r = combine(results, draws, trial_seed=7)
    assert (r.distance_m, r.work_j, r.status, r.seed) == (2.0, 20.0, TrialStatus.COMPLETE, 7)
    assert r.wall_time_s == 1.0 + 2.0 + 3.0  # the episodes' wall times add up
    assert [e.distance_m for e in r.episodes] == [1.0, 6.0, 2.0]
    assert r.extras["episodes"] == 3


def test_a_failed_episode_fails_the_trial_and_the_median_is_of_the_complete_ones():
    # four episodes, the second failed: median of 1, 2, 9 = 2 (of all four it would be 1.75)
    results, draws = _episodes([1.0, 0.5, 2.0, 9.0], [1.0, 2.0, 3.0, 4.0], failed={1})
    r = combine(results, draws, trial_seed=7)
    assert r.status == TrialStatus.FAILED and r.reason == "episode 1 of 4: diverged: nan"
    assert r.distance_m == 2.0 and r.work_j == 3.0
    none_ok, draws = _episodes([1.0, 4.0, 2.0], [1.0, 1.0, 1.0], failed={0, 1, 2})
    assert combine(none_ok, draws, 7).distance_m == 2.0  # none complete: the median of all


def test_the_robust_statistics_by_hand():
    values = [7.0, 1.0, math.nan, 2.0, 6.0]  # the non-finite one left out
    assert statistic(values, "mean") == 4.0
    assert statistic(values, "q25") == 1.75  # linear: 1 + 0.75 * (2 - 1)
    assert statistic(values, "min") == 1.0
    assert math.isnan(statistic([math.inf, math.nan], "mean"))
    with pytest.raises(ValueError, match="median"):
        statistic(values, "median")


def test_a_drawn_friction_changes_what_the_episodes_measure():
    """The same episodes (same seeds) with and without a drawn friction (+-60 %) must travel differently:
    friction is what the feet push against."""
    morph = load_morphology("tetraspine")
    u = random_unit_params(morph, 3)
    cfg = TrialConfig(duration_s=1.0, engine="mujoco")
    plain = run_episodes(morph, u, cfg, 11, RobustSpec(3, {"start_jitter_cm": 0.0}))
    drawn = run_episodes(morph, u, cfg, 11, RobustSpec(3, {"friction": 0.6}))
    scales = [e.friction_scale for e in drawn.episodes]
    assert len(set(scales)) == 3 and all(0.4 <= s <= 1.6 for s in scales)
    assert [e.seed for e in plain.episodes] == [e.seed for e in drawn.episodes]
    for a, b in zip(plain.episodes, drawn.episodes, strict=True):
        assert abs(a.distance_m - b.distance_m) > 1e-4, (a.distance_m, b.distance_m)
