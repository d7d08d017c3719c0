"""The contact guard's spin is the length of the angular velocity vector, |w| = sqrt(wx² + wy² + wz²), times
the body's bounding radius: a body spinning about all three axes at once (2, 3 and 6 rad/s: |w| = 7 rad/s) moves
its tips as fast as one spinning at 7 rad/s about one axis (docs: t = (gap - 0.1 cm) / (2 v))."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from spinefarm.worker.engines.contact_guard import SegmentContactGuard


def _rod_body() -> SimpleNamespace:
    # one rod 10 cm long through the body's centre, 0.5 cm radius: bounding radius 5.5 cm
    return SimpleNamespace(rods=[SimpleNamespace(rotation=np.eye(3), length_cm=10.0, centre_cm=np.zeros(3),
                                                 radius_cm=0.5)])


def test_the_spin_is_the_length_of_the_angular_velocity() -> None:
    guard = SegmentContactGuard([_rod_body(), _rod_body()], [])
    qpos = np.array([[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], [20.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]])  # gap 19 cm
    expected = (19.0 - 0.1) / (2 * 7.0 * 5.5)
    for w in ([2.0, 3.0, 6.0], [0.0, 7.0, 0.0], [-6.0, -2.0, 3.0]):
        qvel = np.zeros((2, 6))
        qvel[1, 3:] = w
        assert guard.free_time_s(qpos, qvel, 10.0)[0] == pytest.approx(expected, rel=1e-12), w
    assert math.isclose(math.hypot(2.0, 3.0, 6.0), 7.0)


def test_the_closing_speed_is_that_of_one_body_relative_to_the_other() -> None:
    """Two bodies moving together (the same velocity, any direction) close no gap; moving apart at v each,
    they close at 2v by the guard's bound |v_a - v_b| (no spin)."""
    guard = SegmentContactGuard([_rod_body(), _rod_body()], [])
    qpos = np.array([[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], [20.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]])  # gap 19 cm
    v = np.array([3.0, 4.0, 12.0])  # 13 cm/s
    qvel = np.zeros((2, 6))
    qvel[0, :3] = qvel[1, :3] = v
    assert guard.free_time_s(qpos, qvel, 10.0) == (10.0, math.inf)
    qvel[1, :3] = -v
    assert guard.free_time_s(qpos, qvel, 10.0)[0] == pytest.approx(18.9 / (2 * 26.0), rel=1e-12)


@pytest.mark.parametrize("v", [[0.0, 0.0, 20.0], [0.0, 20.0, 0.0], [20.0, 0.0, 0.0]])
def test_bodies_away_from_the_origin_are_measured_from_each_other(v) -> None:
    """Rods parallel 20 cm apart along z, both bodies far from the origin (x 100, y 50 cm): body 1 closing at
    20 cm/s straight at body 0 (or past it, along y or x: the same bound, |v| = 20 cm/s)."""
    guard = SegmentContactGuard([_rod_body(), _rod_body()], [])
    qpos = np.array([[100.0, 50.0, -40.0, 1.0, 0.0, 0.0, 0.0], [100.0, 50.0, -20.0, 1.0, 0.0, 0.0, 0.0]])
    qvel = np.zeros((2, 6))
    qvel[1, :3] = -np.array(v)
    # a horizon of 0.5 s: only a pair within 20 cm (+ 0.1) may limit it, so a pair wrongly judged far is skipped
    t, gap = guard.free_time_s(qpos, qvel, 0.5)
    assert gap == pytest.approx(19.0, abs=1e-9)
    assert t == pytest.approx(18.9 / (2 * 20.0), rel=1e-12)
