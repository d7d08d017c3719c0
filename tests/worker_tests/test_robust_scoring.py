"""A robust trial's figures (docs/results.md's robust scoring, worker.trial.robust): the parts are the medians of
the episodes (not their mean), the statistics are worked by hand, and a drawn friction reaches the simulator."""

from __future__ import annotations

import dataclasses
import math

import pytest

from spinefarm.protocol.robust import EpisodeDraw, RobustSpec, parse_randomize, statistic
from spinefarm.protocol.states import TrialStatus
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.worker.trial.robust import combine, run_episodes
from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params
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


@pytest.mark.parametrize("text", ["friction=0", "friction=0.9", "mass=0.0", "mass=0.9", "start_jitter_cm=0",
                                  "start_jitter_cm=10"])
def test_randomize_takes_its_documented_ranges_inclusive(text):
    # docs/results.md, `--randomize`: friction and mass in [0, 0.9], start_jitter_cm in [0, 10]
    key, value = text.split("=")
    assert parse_randomize(text) == {key: float(value)}


@pytest.mark.parametrize("text", ["friction=-0.01", "friction=0.91", "mass=0.95", "start_jitter_cm=10.5",
                                  "friction=nan", "friction=inf"])
def test_randomize_outside_its_ranges_is_refused(text):
    with pytest.raises(ValueError, match="out of range"):
        parse_randomize(text)


def test_episodes_from_1_to_256_and_what_is_robust():
    assert RobustSpec().episodes == 1 and not RobustSpec().active  # one plain episode: not a robust run
    assert RobustSpec(2).active and RobustSpec(1, {"friction": 0.1}).active
    assert RobustSpec(256).episodes == 256 and RobustSpec(1).episodes == 1
    for bad in (0, 257, True, 2.0):
        with pytest.raises(ValueError, match="--episodes out of range"):
            RobustSpec(bad)
    with pytest.raises(ValueError, match="--episodes out of range"):
        RobustSpec(2, rung_episodes=(0, 2), rung_durations_s=(1.0, 5.0))
    spec = RobustSpec(4, rung_episodes=(1, 2, 4), rung_durations_s=(1.0, 3.0, 9.0))
    assert [spec.episodes_for(d) for d in (1.0, 3.0, 9.0, 7.0, None)] == [1, 2, 4, 4, 4]
    for rungs, durations in (((1, 4), (1.0, 3.0, 9.0)), ((4, 1, 2), (1.0, 3.0, 9.0)), ((2, 4), (1.0,))):
        with pytest.raises(ValueError, match="per rung"):
            RobustSpec(4, rung_episodes=rungs, rung_durations_s=durations)
    with pytest.raises(dataclasses.FrozenInstanceError):
        spec.episodes = 3  # a run's settings are not changed in place


def test_robust_settings_round_trip_and_refuse_unknown_fields():
    spec = RobustSpec(3, {"friction": 0.2}, "q25")
    assert RobustSpec.from_dict(spec.to_dict()) == spec and RobustSpec.from_dict({}) == RobustSpec()
    with pytest.raises(ValueError, match="malformed"):
        RobustSpec.from_dict({"episodes": 3, "bogus": 1})
    with pytest.raises(ValueError, match="malformed"):
        RobustSpec.from_dict([("episodes", 3)])
    draw = EpisodeDraw(0, 5)
    assert (draw.friction_scale, draw.mass_scale, draw.start_jitter_cm, draw.rough_seed) == (1.0, 1.0, 0.0, -1)
