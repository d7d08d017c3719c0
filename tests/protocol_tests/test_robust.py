"""Robust scoring as data: --randomize parsing, episode draws, the statistic, episodes on the wire."""

from __future__ import annotations

import math

import numpy as np
import pytest

from spinefarm.cli.main import main
from spinefarm.coordinator.objectives import objective_fn, robust_objective
from spinefarm.protocol.envelope import decode_message, encode_message
from spinefarm.protocol.errors import ConfigError
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.robust import EpisodeResult, RobustSpec, draw_episode, parse_randomize, statistic
from spinefarm.protocol.states import TrialStatus
from spinefarm.protocol.submissions import ResultSubmission, SubmittedResult

BAD_RANDOMIZE = [
    ("", "--randomize is empty"),
    ("friction", "is not NAME=VALUE"),
    ("=0.1", "is not NAME=VALUE"),
    ("gravity=0.1", "unknown name 'gravity'"),
    ("friction=abc", "friction is not a number"),
    ("friction=nan", "friction out of range"),
    ("friction=inf", "friction out of range"),
    ("friction=-0.1", "friction out of range"),
    ("friction=1.5", "friction out of range"),
    ("mass=0.95", "mass out of range"),
    ("start_jitter_cm=11", "start_jitter_cm out of range"),
    ("start_jitter_cm=", "start_jitter_cm is not a number"),
    ("scene=slope", "not a randomisable scene"),
    ("friction=0.1,friction=0.2", "names 'friction' twice"),
    ("friction=0.1,,mass=0.05", "is not NAME=VALUE"),
]


@pytest.mark.parametrize(("text", "message"), BAD_RANDOMIZE)
def test_every_bad_randomize_value_is_a_one_line_error_naming_it_and_what_is_allowed(text, message, capsys,
                                                                                      tmp_path):
    with pytest.raises(ConfigError) as err:
        parse_randomize(text)
    assert message in str(err.value) and "expected" in str(err.value)
    code = main(["search", "tetraspine", "--workers", "0", "--api-port", "-1", "--randomize", text,
                 "--out", str(tmp_path / "r.h5")])
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert code == 2 and len(lines) == 1, lines
    assert lines[0].startswith("spinefarm search: error: ") and message in lines[0]
    assert "received" in lines[0] and "expected" in lines[0]
    assert not (tmp_path / "r.h5").exists()  # nothing was created


def test_bad_episodes_and_statistic_are_refused():
    with pytest.raises(ConfigError, match="--episodes out of range"):
        RobustSpec(episodes=0)
    with pytest.raises(ConfigError, match="--episodes out of range"):
        RobustSpec(episodes=257)
    with pytest.raises(ConfigError, match="--robust is not a statistic"):
        RobustSpec(episodes=4, statistic="median")


def test_a_good_randomize_parses_to_its_values():
    assert parse_randomize("friction=0.1,mass=0.05,start_jitter_cm=0.5,scene=rough") == {
        "friction": 0.1, "mass": 0.05, "start_jitter_cm": 0.5, "scene": "rough"}


def test_draws_come_from_the_trial_seed_and_episode_alone_and_stay_in_range():
    spec = RobustSpec(8, {"friction": 0.1, "mass": 0.05, "start_jitter_cm": 0.5, "scene": "rough"})
    draws = [draw_episode(spec, 12345, k) for k in range(8)]
    assert draws == [draw_episode(spec, 12345, k) for k in range(8)]
    assert len({d.seed for d in draws}) == 8
    assert draws[0] != draw_episode(spec, 12346, 0)
    for d in draws:
        assert 0.9 <= d.friction_scale <= 1.1 and 0.95 <= d.mass_scale <= 1.05
        assert d.start_jitter_cm == 0.5 and d.rough_seed == d.seed
    # a factor not randomised stays 1, and the others keep their draws
    only = RobustSpec(8, {"friction": 0.1})
    assert [draw_episode(only, 12345, k).friction_scale for k in range(8)] == [d.friction_scale for d in draws]
    assert {draw_episode(only, 12345, k).mass_scale for k in range(8)} == {1.0}


def test_the_statistic_matches_a_hand_computation():
    values = [4.0, 1.0, 3.0, 2.0, float("nan")]  # a NaN (never from a complete episode) is left out
    assert statistic(values, "mean") == 2.5
    assert statistic(values, "min") == 1.0
    # q25 of 1, 2, 3, 4 by linear interpolation: position 0.25 * 3 = 0.75 -> 1 + 0.75 * (2 - 1)
    assert statistic(values, "q25") == 1.75
    assert math.isnan(statistic([float("nan")], "mean"))


def _episode(k: int, distance_m: float, status: str = "complete") -> EpisodeResult:
    return EpisodeResult(k, 100 + k, status, "" if status == "complete" else "diverged: x", distance_m,
                         100 * distance_m, 10 * distance_m, 5.0, 5.0 / (9.81 * distance_m), 10.0, 1.0, 1.0 + k / 100,
                         1.0, 0.5, -1)


def test_the_robust_objective_is_the_statistic_of_the_per_episode_objective():
    eps = tuple(_episode(k, d) for k, d in enumerate([0.4, 0.1, 0.3, 0.2]))
    r = TrialResult(TrialStatus.COMPLETE, "", 0.25, 25.0, 2.5, 5.0, 1.0, 10.0, 4.0, 2.0, 7, episodes=eps)
    assert robust_objective(objective_fn("distance"), "q25")(r) == pytest.approx(0.175, abs=1e-15)
    assert robust_objective(objective_fn("speed"), "min")(r) == pytest.approx(1.0)
    assert robust_objective(objective_fn("distance"), "mean")(r) == pytest.approx(0.25)
    # cot_distance per episode: distance / (1 + the episode's own COT), then the mean
    got = robust_objective(objective_fn("cot_distance"), "mean")(r)
    assert got == pytest.approx(np.mean([d / (1 + 5.0 / (9.81 * d)) for d in (0.4, 0.1, 0.3, 0.2)]))


def test_episodes_travel_in_a_result_and_come_back_equal():
    eps = tuple(_episode(k, d) for k, d in enumerate([0.4, 0.1]))
    r = TrialResult(TrialStatus.COMPLETE, "", 0.25, 25.0, 2.5, 5.0, 1.0, 10.0, 4.0, 2.0, 7, trial_id=3,
                    extras={"episodes": 2}, episodes=eps)
    back = decode_message(encode_message(ResultSubmission("w1", (SubmittedResult(9, r),))), ResultSubmission)
    assert back.items[0].result == r
    plain = TrialResult(TrialStatus.COMPLETE, "", 0.25, 25.0, 2.5, 5.0, 1.0, 10.0, 4.0, 2.0, 7, trial_id=3)
    assert "episodes" not in plain.to_dict()


def test_episodes_per_rung_must_match_the_rungs(capsys, tmp_path):
    spec = RobustSpec(8, {}, "mean", rung_episodes=(2, 8), rung_durations_s=(3.0, 10.0))
    assert (spec.episodes_for(3.0), spec.episodes_for(10.0), spec.episodes_for(None)) == (2, 8, 8)
    assert RobustSpec.from_dict(spec.to_dict()) == spec
    for args, message in ((["--episodes", "2,8"], "a list needs --rungs"),
                          (["--episodes", "2,4,8", "--rungs", "3,10"], "one per --rungs duration"),
                          (["--episodes", "two"], "--episodes is not an integer"),
                          (["--episodes", "0"], "--episodes out of range")):
        code = main(["search", "tetraspine", "--workers", "0", "--api-port", "-1", *args,
                     "--out", str(tmp_path / "r.h5")])
        lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
        assert code == 2 and len(lines) == 1 and message in lines[0], lines


def _result(speed_cm_s: float, cot: float) -> TrialResult:
    return TrialResult(status=TrialStatus.COMPLETE, reason="", distance_m=speed_cm_s / 10, ntrt_distance_cm=0.0,
                       speed_cm_s=speed_cm_s, work_j=1.0, cot=cot, sim_time_s=10.0, wall_time_s=1.0, mass_kg=2.0,
                       seed=7)


def test_the_cot_objective_ranks_every_gait_of_the_speed_above_every_slower_one_then_by_cot():
    score = objective_fn("cot:6.13")
    kept = [_result(6.13, 2.5), _result(6.5, 2.1), _result(20.0, 9.0)]
    slower = [_result(6.12, 0.5), _result(3.0, 0.1), _result(0.0, math.inf), _result(math.nan, math.nan)]
    assert min(score(r) for r in kept) > max(score(r) for r in slower)
    assert score(kept[1]) > score(kept[0]) > score(kept[2])  # among the fast ones: the cheaper, the better
    assert score(slower[0]) > score(slower[1]) > score(slower[2]) == score(slower[3]) == 0.0  # the faster, better
    # per episode, as a robust run scores it
    eps = tuple(_episode(k, d) for k, d in enumerate([0.4, 0.1, 0.3, 0.2]))
    r = TrialResult(TrialStatus.COMPLETE, "", 0.25, 25.0, 2.5, 5.0, 1.0, 10.0, 4.0, 2.0, 7, episodes=eps)
    assert robust_objective(objective_fn("cot:3"), "min")(r) == pytest.approx(1.0 / 3)  # speeds 4, 1, 3, 2


@pytest.mark.parametrize("name", ["cot:", "cot:fast", "cot:0", "cot:-1", "cot:nan", "cot:inf", "COT:5"])
def test_a_bad_cot_objective_names_what_was_given_and_what_is_expected(name):
    with pytest.raises(ConfigError) as err:
        objective_fn(name)
    assert name in str(err.value) and ("cot:6.13" in str(err.value) or "cot:MIN_SPEED_CM_S" in str(err.value))
