"""The rest-length motor: speed, acceleration and tension limits, in physical units."""

from __future__ import annotations

import numpy as np
import pytest

from spinefarm.worker.sim.strings import motor_ntrt2014, motor_physical

K, TMAX, V, A = 1000.0, 7000.0, 24.0, 10000.0


def run_motor(target: float, dt: float, seconds: float, length: float = 30.0, rest: float = 30.0):
    rests, speeds = [rest], [0.0]
    u = 0.0
    for _ in range(int(round(seconds / dt))):
        rest, u = motor_physical(rest, target, length, K, TMAX, V, A, 0.1, 0.1, u, dt)
        rests.append(rest)
        speeds.append(u)
    return np.array(rests), np.array(speeds)


@pytest.mark.parametrize("dt", [2e-3, 1e-3, 2.5e-4])
def test_speed_and_acceleration_limits(dt):
    rests, speeds = run_motor(target=25.0, dt=dt, seconds=0.5, length=25.0)  # slack-free shortening
    rate = np.diff(rests) / dt
    assert np.all(np.abs(rate) <= V + 1e-9)
    assert np.all(np.abs(np.diff(speeds)) <= A * dt + 1e-9)
    assert abs(rests[-1] - 25.0) < 1e-9  # arrives and stops at the target
    assert np.max(np.abs(rate)) > 0.99 * V  # and did reach full speed on the way


def test_limits_do_not_depend_on_the_step():
    # time to cover 5 cm at 24 cm/s with 10000 cm/s^2 is 5/24 + 24/10000 s
    times = []
    for dt in (2e-3, 1e-3, 2.5e-4, 1e-4):
        rests, _ = run_motor(target=25.0, dt=dt, seconds=0.5, length=25.0)
        times.append(np.argmax(np.abs(rests - 25.0) < 1e-6) * dt)
    expected = 5.0 / V + V / A
    assert np.allclose(times, expected, rtol=0.02)


def test_no_shortening_above_max_tension():
    # tension k (L - rest) = 1000 * 8 = 8000 > 7000: asked to shorten, the motor must not
    rest, u = 22.0, -20.0  # even when already reeling in
    for _ in range(100):
        new_rest, u = motor_physical(rest, 10.0, 30.0, K, TMAX, V, A, 0.1, 0.1, u, 1e-3)
        if K * (30.0 - rest) > TMAX:
            assert new_rest >= rest
        rest = new_rest
    # it lets out until the tension is back at the limit
    assert abs(K * (30.0 - rest) - TMAX) < 1.0


def test_ntrt2014_motor_caps_are_per_step():
    """NTRT's 2014 motor: per-step change capped at A dt^2 when the string is not already moving at V."""
    rest = 30.0
    new = motor_ntrt2014(rest, 20.0, 30.0, K, TMAX, V, A, 0.1, 0.1, 0.0, 1e-3)
    assert np.isclose(rest - new, A * 1e-6)  # 0.01 cm per step, i.e. 10 cm/s at 1 ms
    new_half = motor_ntrt2014(rest, 20.0, 30.0, K, TMAX, V, A, 0.1, 0.1, 0.0, 5e-4)
    assert np.isclose((rest - new_half) / 5e-4, 5.0)  # and 5 cm/s at 0.5 ms: speed tied to dt
