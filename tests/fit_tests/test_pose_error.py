"""A recorded pose against a simulated one, by hand: the angle between two orientations (q and -q alike) and the
pose error as position and the rotation's arc at a segment's radius (worker.fit.state)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from spinefarm.worker.fit.state import pose_error, rotation_angle


def _pose(xyz, axis, angle_rad):
    """One segment's pose (1, 7): COM cm and the quaternion (x, y, z, w) of `angle_rad` about unit `axis`."""
    s = math.sin(angle_rad / 2)
    return np.array([[*xyz, axis[0] * s, axis[1] * s, axis[2] * s, math.cos(angle_rad / 2)]])


def test_the_angle_between_orientations_is_the_turn_between_them_whatever_the_quaternions_sign():
    upright = _pose((0, 0, 0), (0, 1, 0), 0.0)
    quarter = _pose((0, 0, 0), (0, 1, 0), math.pi / 2)
    assert rotation_angle(quarter, upright) == pytest.approx([math.pi / 2])
    flipped = quarter.copy()
    flipped[:, 3:] *= -1.0    # the same orientation
    assert rotation_angle(flipped, quarter) == pytest.approx([0.0], abs=1e-7)
    assert rotation_angle(_pose((0, 0, 0), (1, 0, 0), 2.0), _pose((0, 0, 0), (1, 0, 0), 0.5)) == pytest.approx([1.5])


def test_the_pose_error_adds_the_position_and_the_rotations_arc_in_quadrature():
    rec = _pose((1.0, 2.0, 3.0), (0, 0, 1), 0.0)
    moved = _pose((4.0, 2.0, 7.0), (0, 0, 1), 0.0)                  # 3 and 4 cm off: 5 cm
    assert pose_error(moved, rec, 10.0) == pytest.approx([5.0])
    turned = _pose((1.0, 2.0, 3.0), (0, 0, 1), 0.12)                # 0.12 rad at 25 cm: a 3 cm arc
    assert pose_error(turned, rec, 25.0) == pytest.approx([3.0])
    both = _pose((4.0, 2.0, 7.0), (0, 0, 1), 0.12)
    assert pose_error(both, rec, 100.0) == pytest.approx([math.hypot(5.0, 12.0)])   # 5 cm and a 12 cm arc
