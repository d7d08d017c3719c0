"""The calibration's figures by hand (docs/engines.md): average ranks with ties, Spearman's rho (none below 3
finite pairs or for a constant side), the top-k overlap and failures, the distance ratio over gaits moving
>= 1 cm in Bullet either way, each threshold inclusive at its documented value, and the key's parts."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from spinefarm.protocol.errors import ConfigError
from spinefarm.worker.tools.calibrate import CalibrationSettings, agreement, decide, ranks, spearman


def test_ranks_share_their_mean_rank_on_ties() -> None:
    assert ranks(np.array([3.0, 1.0, 2.0])).tolist() == [2.0, 0.0, 1.0]
    assert ranks(np.array([1.0, 2.0, 2.0, 5.0])).tolist() == [0.0, 1.5, 1.5, 3.0]
    assert ranks(np.array([4.0, 4.0, 4.0])).tolist() == [1.0, 1.0, 1.0]


def test_spearman_by_hand() -> None:
    assert spearman(np.array([1.0, 2.0, 3.0, 4.0]), np.array([4.0, 3.0, 2.0, 1.0])) == pytest.approx(-1.0)
    # ranks 0, 1.5, 1.5, 3 against 0, 1, 2, 3: 4.5 / sqrt(4.5 x 5)
    assert spearman(np.array([1.0, 2.0, 2.0, 4.0]), np.array([1.0, 2.0, 3.0, 4.0])) == \
        pytest.approx(4.5 / math.sqrt(4.5 * 5.0))
    # a non-finite pair is left out: three finite pairs remain, in the same order
    assert spearman(np.array([1.0, 2.0, math.nan, 4.0]), np.array([1.0, 2.0, 3.0, 9.0])) == pytest.approx(1.0)


def test_spearman_is_none_below_three_pairs_or_for_a_constant_side() -> None:
    assert math.isnan(spearman(np.array([1.0, 2.0, math.nan, 4.0]), np.array([1.0, 2.0, 3.0, math.inf])))
    assert math.isnan(spearman(np.array([1.0, 1.0, 1.0, 1.0]), np.array([1.0, 2.0, 3.0, 4.0])))
    assert math.isnan(spearman(np.array([1.0, 2.0, 3.0, 4.0]), np.array([5.0, 5.0, 5.0, 5.0])))


def test_agreement_counts_failures_and_takes_the_ratio_over_gaits_moving_either_way() -> None:
    bullet = np.array([1.0, -0.5, 0.005, math.nan, 2.0])
    mujoco = np.array([1.1, -0.45, 0.5, 1.0, math.inf])
    a = agreement(bullet, mujoco)
    assert (a["n"], a["top_k"], a["top_overlap"], a["n_moving"]) == (3, 3, 3, 2)
    assert a["failed"] == {"bullet": 1, "mujoco": 1}
    assert a["median_distance_ratio"] == pytest.approx(1.0)      # 1.1 and 0.9; the 5 mm gait left out
    assert agreement(np.array([0.001, 0.002, 0.0]), np.array([1.0, 2.0, 3.0]))["median_distance_ratio"] is None


def test_the_top_overlap_is_of_the_best_k_in_each_engine() -> None:
    bullet = np.array([5.0, 4.0, 3.0, 2.0, 1.0])
    mujoco = np.array([5.0, 1.0, 4.0, 3.0, 2.0])   # top 2: {0, 1} in Bullet, {0, 2} in MuJoCo
    a = agreement(bullet, mujoco, top=2)
    assert (a["top_k"], a["top_overlap"]) == (2, 1)
    assert agreement(bullet, mujoco, top=3)["top_overlap"] == 2   # {0, 1, 2} and {0, 2, 3}


def agree(rho: float, overlap: int, ratio: float | None, top_k: int = 10) -> dict:
    return {"spearman": rho, "top_overlap": overlap, "top_k": top_k, "median_distance_ratio": ratio}


def test_every_threshold_holds_at_its_documented_value() -> None:
    assert decide(agree(0.9, 8, 0.9))[0] == "mujoco"
    assert decide(agree(0.9, 8, 1.1))[0] == "mujoco"
    assert decide(agree(0.8999, 8, 1.0))[0] == "bullet"
    assert decide(agree(1.0, 8, 1.1001))[0] == "bullet"
    assert decide(agree(1.0, 8, 0.8999))[0] == "bullet"
    assert decide(agree(math.nan, 10, 1.0))[0] == "bullet"
    assert decide(agree(1.0, 10, None))[0] == "bullet"
    # 5 gaits: ceil(8 x 5 / 10) = 4 of 5 needed; 3 gaits: ceil(2.4) = 3
    assert [decide(agree(1.0, n, 1.0, 5))[0] for n in (3, 4)] == ["bullet", "mujoco"]
    assert [decide(agree(1.0, n, 1.0, 3))[0] for n in (2, 3)] == ["bullet", "mujoco"]


def test_the_key_leaves_out_the_processes_and_an_unset_step_only() -> None:
    base = CalibrationSettings()
    assert CalibrationSettings(jobs=2).key() == base.key()
    others = [CalibrationSettings(dt_s=0.002), CalibrationSettings(auto_dt=True), CalibrationSettings(gaits=41),
              CalibrationSettings(profile=(("ground_friction", 1.1),)), CalibrationSettings(settle_s=0.5)]
    keys = {s.key() for s in others}
    assert len(keys) == len(others) and base.key() not in keys


def test_more_bests_than_search_trials_are_refused() -> None:
    CalibrationSettings(search_trials=5, bests=5)
    with pytest.raises(ConfigError, match="bests"):
        CalibrationSettings(search_trials=5, bests=6)


@pytest.mark.parametrize("field", [dict(gaits=100_001), dict(gaits=2), dict(search_trials=100_001),
                                   dict(bests=100_001), dict(duration_s=0.0), dict(duration_s=3600.5),
                                   dict(settle_s=-0.5), dict(settle_s=60.5), dict(jobs=0), dict(jobs=100_001),
                                   dict(dt_s=5e-7), dict(dt_s=0.03)])
def test_settings_outside_their_ranges_are_refused(field: dict) -> None:
    with pytest.raises(ConfigError):
        CalibrationSettings(**field)


def test_settings_at_their_range_ends_are_taken() -> None:
    CalibrationSettings(gaits=100_000, search_trials=100_000, bests=100_000, duration_s=3600.0, settle_s=60.0,
                        jobs=100_000, dt_s=0.02)
    CalibrationSettings(gaits=3, search_trials=0, bests=0, duration_s=0.001, settle_s=0.0, jobs=1, dt_s=1e-6)


def test_settings_are_fixed_once_made() -> None:
    # the key is taken from them and the cache is found by it: a changed field would file a result wrongly
    s = CalibrationSettings()
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.gaits = 41  # type: ignore[misc]
    assert hash(s) == hash(CalibrationSettings())


def test_a_gait_moving_exactly_one_cm_counts_and_none_moving_is_said() -> None:
    # docs/engines.md: the ratio is taken over gaits that move >= 1 cm in Bullet
    bullet = np.array([0.01, 0.009, 0.5, 0.2])
    agree = agreement(bullet, bullet * 1.0)
    assert agree["n_moving"] == 3 and agree["median_distance_ratio"] == 1.0
    still = agreement(np.array([0.001, 0.002, 0.003]), np.array([0.001, 0.002, 0.003]))
    assert still["median_distance_ratio"] is None
    assert "distance ratio none (no gait moves) outside [0.9, 1.1]" in decide(still)[1]
