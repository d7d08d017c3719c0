"""The `ntrt-followable` space: NTRT's couplings with node targets the motors can follow."""

from __future__ import annotations

import math

import numpy as np
import pytest

from spinefarm.protocol.errors import ConfigError
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.spaces import controller_space, followable_limits, param_space
from spinefarm.worker.trial.simulation import TrialConfig, simulate

BUILT_INS = ["tetraspine", "tetrahedral-complex", "octahedral-complex", "ribbed"]


@pytest.mark.parametrize("name", BUILT_INS)
def test_bounds_lie_inside_ntrt_and_every_corner_is_followable(name):
    morph = load_morphology(name)
    ntrt, bounded = controller_space(morph, "ntrt"), controller_space(morph, "ntrt-followable")
    assert bounded.param_space.names == ntrt.param_space.names
    assert np.all(bounded.param_space.lows >= ntrt.param_space.lows)
    assert np.all(bounded.param_space.highs <= ntrt.param_space.highs)
    assert np.array_equal(bounded.param_space.lows[2:], ntrt.param_space.lows[2:])  # couplings as NTRT's
    mats, gains = dict(morph.structure.string_materials), dict(morph.control.impedance)
    for corner in ([1.0, 1.0], [0.0, 0.0], [1.0, 0.0], [0.0, 1.0]):
        u = np.full(len(bounded.param_space), 0.5)
        u[:2] = corner
        net = bounded.network(bounded.param_space.from_unit(u))
        f_hz, a_cm_s = abs(net.omega_rad_s[0]) / (2 * math.pi), abs(net.amplitude_cm_s[0])
        for s in net.node_string:
            tag = morph.structure.strings[s].tag
            v, k, b = mats[tag].motor_speed_cm_s, mats[tag].stiffness_n_per_m, gains[tag].velocity_gain_n_s_per_m
            assert a_cm_s <= v + 1e-9
            assert 2 * math.pi * f_hz * b * a_cm_s / k <= v + 1e-9  # rest-length speed the impedance law asks
            assert 2 * math.pi * f_hz * a_cm_s <= mats[tag].motor_accel_cm_s2 + 1e-9
    # NTRT's own range asks for far more: 90 Hz at 90 cm/s for node range [0, 30]
    f_max, _ = followable_limits(morph, ntrt.node_strings)
    assert 3 * ntrt.param_space.highs[0] > 10 * f_max


def test_the_followable_space_runs_and_unknown_spaces_are_refused():
    morph = load_morphology("tetraspine-ntrt")
    u = np.random.default_rng(4).random(len(param_space(morph, "ntrt-followable")))
    r = simulate(morph, u, TrialConfig(duration_s=0.5, controller="ntrt-followable")).result
    assert r.ok and math.isfinite(r.distance_m)
    with pytest.raises(ConfigError, match="no controller space 'sidewinding-followable'"):
        param_space(morph, "sidewinding-followable")
