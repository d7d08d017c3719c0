"""The contact guard's geometry (worker/engines/contact_guard.py): the shortest distance between two segments,
by hand for each case of the closest-point rule (skew, parallel, a point at either side, ends clamped) and
against a brute-force search over points of both segments; a MuJoCo quaternion's rotation by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from spinefarm.worker.engines.contact_guard import _rotate, _segment_distance


def dist(p1, q1, p2, q2) -> float:
    return _segment_distance(*(np.array(v, dtype=float) for v in (p1, q1, p2, q2)))


@pytest.mark.parametrize(("p1", "q1", "p2", "q2", "expected"), [
    ((0, 0, 0), (2, 0, 0), (1, -1, 3), (1, 1, 3), 3.0),                  # skew, closest points inside both
    ((0, 0, 0), (4, 0, 0), (1, 2, 0), (3, 2, 0), 2.0),                   # parallel, overlapping
    ((0, 0, 0), (1, 0, 0), (3, 1, 0), (5, 1, 0), math.sqrt(5.0)),        # parallel, end to end
    ((0, 5, 0), (0, 5, 0), (-1, 0, 0), (1, 0, 0), 5.0),                  # a point over a segment
    ((3, 4, 0), (3, 4, 0), (-1, 0, 0), (1, 0, 0), math.sqrt(20.0)),      # a point past its end
    ((-1, 0, 0), (1, 0, 0), (3, 4, 0), (3, 4, 0), math.sqrt(20.0)),      # the same, sides swapped
    ((-1, 0, 0), (1, 0, 0), (-3, 4, 0), (-3, 4, 0), math.sqrt(20.0)),    # past the other end
    ((0, 0, 0), (0, 0, 0), (1, 2, 2), (1, 2, 2), 3.0),                   # two points
    ((0, 0, 0), (2, 0, 0), (5, -3, 1), (5, -1, 1), math.sqrt(11.0)),     # both clamped, t > 1
    ((0, 0, 0), (2, 0, 0), (5, 1, 1), (5, 3, 1), math.sqrt(11.0)),       # both clamped, t < 0
    ((0, 0, 0), (2, 0, 0), (-3, -1, 1), (-3, 1, 1), math.sqrt(10.0)),    # s clamped below
])
def test_segment_distance_by_hand(p1, q1, p2, q2, expected) -> None:
    assert dist(p1, q1, p2, q2) == pytest.approx(expected, abs=1e-12)
    assert dist(p2, q2, p1, q1) == pytest.approx(expected, abs=1e-12)   # symmetric


def test_segment_distance_against_brute_force() -> None:
    rng = np.random.default_rng(3)
    grid = np.linspace(0.0, 1.0, 401)
    for _ in range(40):
        p1, q1, p2, q2 = rng.uniform(-3, 3, (4, 3))
        a = p1 + grid[:, None] * (q1 - p1)
        b = p2 + grid[:, None] * (q2 - p2)
        brute = np.sqrt(((a[:, None, :] - b[None, :, :]) ** 2).sum(-1)).min()
        got = _segment_distance(p1, q1, p2, q2)
        # the grid's points are on the segments, so it never finds less; a 1/400 step finds within ~0.03
        assert got <= brute + 1e-9 and got == pytest.approx(brute, abs=0.03)


@pytest.mark.parametrize(("q", "v", "expected"), [
    ((math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4)), (1, 0, 0), (0, 1, 0)),   # 90 degrees about z
    ((math.cos(math.pi / 4), math.sin(math.pi / 4), 0, 0), (0, 1, 0), (0, 0, 1)),   # 90 degrees about x
    ((math.cos(math.pi / 4), 0, math.sin(math.pi / 4), 0), (0, 0, 1), (1, 0, 0)),   # 90 degrees about y
    ((math.cos(math.pi / 4), 0, math.sin(math.pi / 4), 0), (1, 0, 0), (0, 0, -1)),
    ((math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4)), (0, 1, 0), (-1, 0, 0)),
    ((math.cos(math.pi / 4), math.sin(math.pi / 4), 0, 0), (0, 0, 1), (0, -1, 0)),
    ((0, 1, 0, 0), (0, 1, 2), (0, -1, -2)),                                          # 180 degrees about x
    ((1, 0, 0, 0), (3, -2, 5), (3, -2, 5)),                                          # none
])
def test_rotate_by_a_mujoco_quaternion(q, v, expected) -> None:
    out = np.zeros(3)
    _rotate(np.array(q, dtype=float), np.array(v, dtype=float), out)
    assert out == pytest.approx(expected, abs=1e-12)
