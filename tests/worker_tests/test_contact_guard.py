"""The MuJoCo contact guard (worker.engines.contact_guard) on two rods, figures by hand: no contact can form
for t = (gap - 0.1 cm) / (2 v), v the largest closing speed of any two points, |v_a - v_b| plus each body's
spin times its bounding radius, and each body's rods turned by its quaternion."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from spinefarm.worker.engines.contact_guard import MIN_CLEARANCE_CM, SAFETY_FACTOR, SegmentContactGuard


def _rod_body():
    # one rod 10 cm long along the body's y axis, 0.5 cm radius, through the body's centre: bounding radius 5.5
    rod = SimpleNamespace(rotation=np.eye(3), length_cm=10.0, centre_cm=np.zeros(3), radius_cm=0.5)
    return SimpleNamespace(rods=[rod])


def _state(b_at_x_cm: float, b_quat=(1.0, 0.0, 0.0, 0.0)):
    qpos = np.array([[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], [b_at_x_cm, 0.0, 0.0, *b_quat]])
    return qpos, np.zeros((2, 6))


def test_the_documented_margins():
    assert (SAFETY_FACTOR, MIN_CLEARANCE_CM) == (2.0, 0.1)


def test_a_spinning_segment_closes_the_gap_as_fast_as_its_tips_move():
    guard = SegmentContactGuard([_rod_body(), _rod_body()], [])
    qpos, qvel = _state(20.0)  # parallel rods 20 cm apart: gap 19 cm
    assert guard.free_time_s(qpos, qvel, 1.0) == (1.0, math.inf)  # at rest: nothing limits
    qvel[0, 5] = 10.0  # body 0 spins at 10 rad/s about z, its centre still: tips at 55 cm/s
    t, gap = guard.free_time_s(qpos, qvel, 1.0)
    assert gap == pytest.approx(19.0, abs=1e-12)
    assert t == pytest.approx((19.0 - 0.1) / (2 * 10.0 * 5.5), rel=1e-12)
    qvel[1, 3] = 4.0  # the other spins too (about x): both radii count
    assert guard.free_time_s(qpos, qvel, 1.0)[0] == pytest.approx(18.9 / (2 * (55.0 + 22.0)), rel=1e-12)


def test_a_turned_segment_is_measured_where_its_quaternion_puts_it():
    guard = SegmentContactGuard([_rod_body(), _rod_body()], [])
    half = math.sqrt(0.5)
    qpos, qvel = _state(20.0, (half, 0.0, 0.0, half))  # body 1 turned 90 deg about z: its rod lies along x
    qvel[1, 0] = -100.0  # and flies at body 0 at 1 m/s
    t, gap = guard.free_time_s(qpos, qvel, 1.0)
    assert gap == pytest.approx(20.0 - 5.0 - 1.0, abs=1e-9)  # its near tip at x = 15
    assert t == pytest.approx((14.0 - 0.1) / (2 * 100.0), rel=1e-9)
    # an excluded pair (a scene that does not let them collide) is not watched
    assert SegmentContactGuard([_rod_body(), _rod_body()], [(1, 0)]).free_time_s(qpos, qvel, 1.0) == (1.0, math.inf)
