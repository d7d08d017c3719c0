"""`--engine auto`'s rule (docs/engines.md, worker.tools.calibrate): MuJoCo screens when Spearman's rho >= 0.9, the
top-10 overlap >= 8 of 10 and the median MuJoCo/Bullet distance ratio lies in [0.9, 1.1], the ratio over the
gaits that move (>= 1 cm) in Bullet. Each threshold is probed on both sides with figures worked by hand:
rho = 1 - 6 sum(d^2) / (n (n^2 - 1)) for ranks without ties."""

from __future__ import annotations

import numpy as np
import pytest

from spinefarm.worker.tools.calibrate import agreement, decide


def _swapped(n: int, pairs) -> tuple[np.ndarray, np.ndarray]:
    """Bullet: gaits 0.1 .. n/10 m, distinct; MuJoCo: the same distances with the given ranks swapped."""
    bullet = np.arange(1, n + 1) / 10.0
    mujoco = bullet.copy()
    for i, j in pairs:
        mujoco[[i, j]] = mujoco[[j, i]]
    return bullet, mujoco


def _rho(n: int, pairs) -> float:
    return 1.0 - 6.0 * sum(2 * (i - j) ** 2 for i, j in pairs) / (n * (n * n - 1))


@pytest.mark.parametrize(("pairs", "choice"), [
    ([(0, 8)], "mujoco"),                   # sum d^2 = 128: rho 0.9038
    ([(0, 8), (10, 11)], "mujoco"),         # 130: rho 0.9023
    ([(0, 8), (10, 12)], "bullet"),         # 136: rho 0.8977, just under 0.9
    ([(0, 9)], "bullet"),                   # 162: rho 0.8782 (passes a looser 0.85 or 0.7)
])
def test_rho_threshold_is_0_9(pairs, choice):
    # swaps among the slowest ten of twenty: the top ten stay the same, the ratios' median stays 1
    bullet, mujoco = _swapped(20, pairs)
    agree = agreement(bullet, mujoco)
    assert agree["spearman"] == pytest.approx(_rho(20, pairs), abs=1e-12)
    assert agree["top_overlap"] == 10
    assert decide(agree)[0] == choice


@pytest.mark.parametrize(("pairs", "overlap", "choice"), [
    ([(29, 30)], 9, "mujoco"),
    ([(29, 30), (28, 31)], 8, "mujoco"),
    ([(29, 30), (28, 31), (27, 32)], 7, "bullet"),   # rho still 0.9934
])
def test_top_overlap_threshold_is_8_of_10(pairs, overlap, choice):
    # forty gaits; swapping across the top ten's edge (ranks 29 | 30) trades members one for one
    bullet, mujoco = _swapped(40, pairs)
    agree = agreement(bullet, mujoco)
    assert (agree["top_k"], agree["top_overlap"]) == (10, overlap)
    assert agree["spearman"] > 0.99
    assert decide(agree)[0] == choice


def test_fewer_gaits_scale_the_overlap_needed():
    # five gaits: top 5, 8 of 10 -> 4 of 5 needed
    bullet = np.array([0.1, 0.2, 0.3, 0.4, 0.5])
    agree = agreement(bullet, bullet.copy(), top=5)
    assert (agree["top_k"], agree["top_overlap"]) == (5, 5)
    assert decide(agree)[0] == "mujoco"


@pytest.mark.parametrize(("factor", "choice"), [(0.88, "bullet"), (0.92, "mujoco"), (1.08, "mujoco"),
                                                (1.12, "bullet"), (1.25, "bullet")])
def test_ratio_band_is_0_9_to_1_1(factor, choice):
    bullet = np.arange(1, 21) / 10.0
    agree = agreement(bullet, factor * bullet)
    assert agree["median_distance_ratio"] == pytest.approx(factor, rel=1e-12)
    assert agree["spearman"] == pytest.approx(1.0) and agree["top_overlap"] == 10
    assert decide(agree)[0] == choice


def test_the_ratio_counts_only_gaits_that_move_in_bullet():
    """Ten gaits move alike in both (ratio 1); eleven stand still in Bullet (< 1 cm) but move 0.5 m in MuJoCo:
    they are left out of the ratio (counted in, the median would be ~100). Gaits that move in Bullet and stand
    still in MuJoCo are in it: ten at ratio 0.002 beside ten at 1 give a median of 0.501."""
    moving = np.arange(1, 11) / 10.0
    still_in_bullet = np.arange(1, 12) / 2000.0  # 0.5 mm .. 5.5 mm
    bullet = np.concatenate([moving, still_in_bullet])
    mujoco = np.concatenate([moving, np.full(11, 0.5)])
    agree = agreement(bullet, mujoco)
    assert agree["n_moving"] == 10 and agree["median_distance_ratio"] == 1.0
    stuck = agreement(np.concatenate([moving, np.full(10, 0.5)]), np.concatenate([moving, np.full(10, 0.001)]))
    assert stuck["n_moving"] == 20
    assert stuck["median_distance_ratio"] == pytest.approx((1.0 + 0.002) / 2)
    nothing = agreement(still_in_bullet, still_in_bullet.copy())
    assert nothing["median_distance_ratio"] is None and decide(nothing)[0] == "bullet"
