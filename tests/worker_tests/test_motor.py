"""The rest-length motor: speed, acceleration and tension limits, in physical units."""

from __future__ import annotations

import numpy as np
import pytest

from spinefarm.worker.sim.strings import motor_ntrt2014, motor_ntrt2026, motor_physical

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


def test_ntrt2026_motor_moves_v_dt_a_step_without_an_acceleration_limit():
    """NTRT's current motor (spec 3.3 [H]): each step's move is the asked-for change clamped to V dt, whatever
    the string's elongation rate. NTRT's recorded TetraSpine runs (V = 7) let the inner strings' rest lengths
    out of their start by exactly 0.07 cm in their first 10 steps."""
    v_h = 7.0
    rest = 24.189064495158576  # ntrt-recordings TetraSpine random-00, string 3: start length, t = 0.01 rest 24.119064
    for _ in range(10):
        rest = motor_ntrt2026(rest, 20.0, 24.2, 10000.0, TMAX, v_h, 0.1, 0.1, 1e-3)
    assert np.isclose(rest, 24.119064, atol=1e-6)
    assert np.isclose(motor_ntrt2026(30.0, 29.999, 30.0, K, TMAX, V, 0.1, 0.1, 1e-3), 29.999)  # small: all of it
    assert np.isclose(motor_ntrt2026(30.0, 20.0, 30.0, K, TMAX, V, 0.1, 0.1, 5e-4), 30.0 - V * 5e-4)
    # above the tension limit the target moves out to L - T_max / k, so the motor lets out
    assert np.isclose(motor_ntrt2026(22.0, 10.0, 30.0, K, TMAX, V, 0.1, 0.1, 1e-3), 22.0 + V * 1e-3)
    assert motor_ntrt2026(0.102, 0.0, 0.2, K, TMAX, V, 0.1, 0.1, 1e-3) == 0.1  # never below the minimum
