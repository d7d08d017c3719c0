"""The CPG at its own step: one RK4 step per update, one update ahead, setpoints interpolated in between;
held exactly where the spec fixes the update interval; every physics step on the Bullet judge."""

from __future__ import annotations

import math

import numpy as np
import pytest

from spinefarm.protocol.errors import ConfigError
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.worker.control.cpg import SLOW_RATE_STEP, CpgNetwork
from spinefarm.worker.control.law import ControlLaw
from spinefarm.worker.sim import strings as sk
from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, simulate, simulate_batch

A = 20.0  # the amplitude rate a (1/s), CpgNetwork's default
DT = 1e-3


def uncoupled(omega: tuple[float, float], amp: tuple[float, float]) -> CpgNetwork:
    return CpgNetwork(node_string=np.array([0, 1]), omega_rad_s=np.array(omega), amplitude_cm_s=np.array(amp),
                      indptr=np.array([0, 0, 0]), source=np.zeros(0, dtype=np.int64), weight=np.zeros(0),
                      phase_rad=np.zeros(0))


def exact_output(t: float, omega: np.ndarray, amp: np.ndarray) -> np.ndarray:
    """x = r cos(omega t) with r critically damped from rest: r = R (1 - (1 + a t / 2) e^(-a t / 2))."""
    return amp * (1 - (1 + A * t / 2) * math.exp(-A * t / 2)) * np.cos(omega * t)


def setpoints(networks: list[CpgNetwork], own_step_s: float | None, n_steps: int) -> tuple[ControlLaw, np.ndarray]:
    """The setpoints (steps, worlds, nodes) the strings read, from a law with no strings."""
    empty = (np.zeros((0, sk.N_PARAM)), np.zeros((0, sk.N_STATE)))
    geom = (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros((0, 3)))
    law = ControlLaw(networks, [empty] * len(networks), geom, 1, None, "physical")
    law.begin_phase(1, DT, own_step_s)
    poses = np.zeros((len(networks), 1, 7))
    poses[..., 6] = 1.0
    active = np.ones(len(networks), dtype=bool)
    out = []
    for _ in range(n_steps):
        assert law.step(poses, active) == 0
        out.append(law.cpg_output_cm_s.copy())
    return law, np.array(out)


def test_interpolated_setpoints_keep_the_hand_derived_bound_and_are_exact_at_the_updates():
    omega, amp = np.array([25.0, 60.0]), np.array([3.0, 5.0])
    net = uncoupled((25.0, 60.0), (3.0, 5.0))
    every = int(0.004 / DT)  # own step SLOW_RATE_STEP / 60 = 4.2 ms, capped at 4 ms
    law, got = setpoints([net], 0.004, 400)
    assert law.cpg_every.tolist() == [every]
    exact = np.array([exact_output((n + 1) * DT, omega, amp) for n in range(400)])
    err = np.abs(got[:, 0] - exact)
    at_updates = np.arange(400) % every == every - 1
    assert err[at_updates].max() < 1e-6 * amp.max()  # phase exact under RK4, amplitude at a h = 0.08
    # between updates: linear interpolation over H is within H^2 / 8 max|x''|, |x''| <= R (omega + a)^2
    bound = (every * DT) ** 2 / 8 * amp * (omega + A) ** 2
    assert (err[~at_updates] <= bound + 1e-6).all()
    assert err[~at_updates].max() > 1e-3  # the setpoints in between are interpolated, not the exact output
    held = np.array([exact_output((n // every) * every * DT, omega, amp) for n in range(400)])
    assert (np.abs(held - exact) > bound).any()  # holding the last update instead would break the bound


def test_every_world_takes_its_own_step_and_a_fast_network_every_physics_step():
    slow, fast = uncoupled((25.0, 60.0), (3.0, 5.0)), uncoupled((600.0, 50.0), (3.0, 5.0))
    law, got = setpoints([slow, fast], 0.004, 100)
    # SLOW_RATE_STEP / 600 = 0.42 ms: below the physics step, so every step and held, as before
    assert SLOW_RATE_STEP / 600.0 < DT and law.cpg_every.tolist() == [4, 1]
    _, alone = setpoints([fast], None, 100)
    assert np.array_equal(got[:, 1], alone[:, 0])
    _, slow_alone = setpoints([slow], 0.004, 100)
    assert np.array_equal(got[:, 0], slow_alone[:, 0])


def _distances(morph, controller, cfg, seeds) -> list[float]:
    return [simulate(morph, random_unit_params(morph, s, controller), cfg, s, controller=controller).result.distance_m
            for s in seeds]


def test_a_slow_network_at_its_own_step_moves_within_the_accuracy_bar_of_every_step():
    """Sidewinding networks (rates under 101/s) take 2 ms CPG steps on MuJoCo by default; the distance of a
    short trial stays within docs/accuracy.md's bar (1 %) of the CPG at every physics step."""
    m = load_morphology("tetraspine")
    own = _distances(m, "sidewinding", TrialConfig(duration_s=1.0, engine="mujoco"), (1, 2, 3))
    every = _distances(m, "sidewinding", TrialConfig(duration_s=1.0, engine="mujoco", cpg_step_s=0.0), (1, 2, 3))
    assert own != every  # the own step ran
    for o, e in zip(own, every, strict=True):
        assert abs(o - e) <= 0.01 * max(abs(e), 0.01)


def test_the_fused_loop_and_a_batch_give_the_bits_of_single_stepwise_runs_at_the_own_step():
    m = load_morphology("tetraspine")
    us = [random_unit_params(m, s, "sidewinding") for s in (4, 5)]
    cfg = TrialConfig(duration_s=0.3, engine="mujoco", pose_jitter_cm=0.01)
    batch = simulate_batch(m, us, cfg, [4, 5], controller="sidewinding")
    rec = TrialConfig(duration_s=0.3, engine="mujoco", pose_jitter_cm=0.01, record_every_s=0.01)
    singles = [simulate(m, u, rec, s, controller="sidewinding") for u, s in zip(us, (4, 5), strict=True)]
    assert [b.result.distance_m for b in batch] == [s.result.distance_m for s in singles]
    assert len({b.result.distance_m for b in batch}) == 2


@pytest.mark.parametrize(("robot", "controller", "cfg"), [
    ("octahedral-complex", None, {}),  # NTRT's controlTime 0.1 s: held for 0.1 s, as the spec fixes it
    ("tetraspine", "sidewinding", {"cpg_update_period_s": 1e-3}),  # an update interval asked for explicitly
])
def test_a_fixed_update_interval_is_kept_to_the_bit(robot, controller, cfg):
    m = load_morphology(robot)
    own = TrialConfig(duration_s=0.3, engine="mujoco", cpg_step_s=0.004, **cfg)
    every = TrialConfig(duration_s=0.3, engine="mujoco", cpg_step_s=0.0, **cfg)
    assert _distances(m, controller, own, (1, 2)) == _distances(m, controller, every, (1, 2))


def test_the_judge_runs_the_cpg_every_step_and_a_bad_step_is_refused():
    assert TrialConfig().cpg_own_step_s is None  # Bullet: the shipped figures' bits
    assert TrialConfig(engine="mujoco").cpg_own_step_s == 0.004
    assert TrialConfig(engine="mujoco", cpg_step_s=0.0).cpg_own_step_s is None
    # unset, the config's dict and hash are those of configs written before the setting existed
    assert "cpg_step_s" not in TrialConfig().to_dict() and TrialConfig().config_hash() == "ed75f80bb448abc9"
    with pytest.raises(ConfigError, match="cpg_step_s") as err:
        TrialConfig(cpg_step_s=-0.001)
    assert "\n" not in str(err.value)
