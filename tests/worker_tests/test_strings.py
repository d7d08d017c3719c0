"""String law checks against analytic results, with the production kernel and pybullet."""

from __future__ import annotations

import math

import numpy as np
import pybullet as pb
import pytest

from spinefarm.worker.engines.couple import wrench_to_force_pairs
from spinefarm.worker.sim import strings as sk
from tests.worker_tests.helpers import ENGINES, PassiveRig, mass_between_anchors, two_rod_structure


@pytest.mark.parametrize("engine", ENGINES)
def test_string_oscillates_at_sqrt_k_over_m(engine):
    """A mass held between two fixed anchors by two taut strings oscillates at sqrt(2 k / m).

    (A tension-only string cannot hold a mass alone without gravity; two opposing, pre-stretched
    strings keep both taut for amplitudes below the pre-stretch.) Anchors are 1e6 times heavier.
    """
    k = 1000.0
    rig = PassiveRig(mass_between_anchors(10.0, anchor_density=0.014 * 1e6, stiffness=k),
                     rest_cm=np.array([9.0, 9.0]), dt=1e-4, engine=engine)  # 1 cm pre-stretch each
    m = rig.bodies[1].mass_kg
    omega = math.sqrt(2 * k / m)
    amplitude_cm = 0.5
    rig.scene.set_velocity(1, [amplitude_cm * omega, 0, 0])
    xs = np.array([rig.step()[1, 0] for _ in range(int(0.5 / rig.dt))])
    rig.close()
    assert np.all(rig.bank.tension > 0)
    assert abs(np.ptp(xs) / 2 - amplitude_cm) < 0.01 * amplitude_cm
    crossings = np.flatnonzero((xs[:-1] < 0) & (xs[1:] >= 0))
    period_s = (crossings[-1] - crossings[0]) / (len(crossings) - 1) * rig.dt
    expected_s = 2 * math.pi / omega
    assert len(crossings) >= 5
    assert abs(period_s - expected_s) / expected_s < 0.005


@pytest.mark.parametrize("engine", ENGINES)
def test_slack_string_does_not_push(engine):
    spec = two_rod_structure(10.0)
    rig = PassiveRig(spec, rest_cm=np.array([12.0]), dt=1e-3, engine=engine)  # 2 cm of slack
    rig.scene.set_velocity(1, [-5.0, 0, 0])
    for _ in range(200):  # 0.2 s at 5 cm/s closes 1 cm: the string stays slack
        rig.step()
    vel = rig.scene.velocities()[0]
    rig.close()
    assert np.all(rig.bank.tension == 0.0)
    assert np.allclose(vel[1, :3], [-5.0, 0, 0], atol=1e-9)
    assert np.allclose(vel[0, :3], 0.0, atol=1e-12)


def _one_string_kernel(length_now: float, length_prev: float, rest: float, k: float, b: float, dt: float):
    poses = np.array([[0, 0, 0, 0, 0, 0, 1.0], [length_now, 0, 0, 0, 0, 0, 1.0]])
    params = np.zeros((1, sk.N_PARAM))
    params[0, sk.P_K], params[0, sk.P_B], params[0, sk.P_NODE] = k, b, -1
    state = np.zeros((1, sk.N_STATE))
    state[0, sk.S_REST], state[0, sk.S_LPREV] = rest, length_prev
    bank = sk.StringBank(2, [0], [1], np.zeros((1, 3)), np.zeros((1, 3)), params, state)
    assert bank.step(poses, np.zeros(0), dt, sk.MOTOR_PHYSICAL) == sk.STATUS_OK
    return bank


def test_damping_is_clamped_to_the_spring_force():
    # stretch 0.1 cm -> spring 100; lengthening at 100 cm/s with b = 50 -> damping 5000, clamped to 100
    bank = _one_string_kernel(10.1, 10.0, 10.0, 1000.0, 50.0, 1e-3)
    assert np.isclose(bank.string_force[0, 0], 200.0)  # pulls end a toward b with F_s + clamp
    # shortening fast: damping -5000 clamped to -100 -> net force zero, never pushing
    bank = _one_string_kernel(10.1, 10.2, 10.0, 1000.0, 50.0, 1e-3)
    assert np.isclose(bank.string_force[0, 0], 0.0)
    # slow motion: damping below the clamp passes through unchanged
    bank = _one_string_kernel(10.1, 10.0999, 10.0, 1000.0, 1.0, 1e-3)
    assert np.isclose(bank.string_force[0, 0], 100.0 + 1.0 * 0.1)


def test_force_pair_matches_net_wrench():
    rng = np.random.default_rng(3)
    poses = np.zeros((3, 7))
    poses[:, :3] = rng.normal(size=(3, 3)) * 10
    poses[:, 6] = 1.0
    force = rng.normal(size=(3, 3)) * 100
    torque = rng.normal(size=(3, 3)) * 1000
    torque[2] = 0.0  # degenerate direction must still work
    pts, fs = np.zeros((6, 3)), np.zeros((6, 3))
    wrench_to_force_pairs(poses, force, torque, pts, fs)
    for b in range(3):
        f = fs[2 * b] + fs[2 * b + 1]
        t = np.cross(pts[2 * b] - poses[b, :3], fs[2 * b]) + np.cross(pts[2 * b + 1] - poses[b, :3], fs[2 * b + 1])
        assert np.allclose(f, force[b])
        assert np.allclose(t, torque[b], atol=1e-9)


def test_force_pairs_match_per_anchor_application_in_pybullet():
    """The net-wrench shortcut against applying each string's force at its two anchors."""
    from spinefarm.robot.bodies import build_bodies, build_strings
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.robot.scene import GroundSpec
    from spinefarm.worker.engines.bullet import BulletPhysics
    from spinefarm.worker.trial.simulation import string_tables

    morph = load_morphology("tetraspine-ntrt")
    bodies = build_bodies(morph.structure)
    geom = build_strings(morph.structure, bodies)
    finals = []
    for per_anchor in (False, True):
        params, state = string_tables(morph, geom.start_length_cm, {})
        bank = sk.StringBank(len(bodies), geom.body_a, geom.body_b, geom.anchor_a_cm, geom.anchor_b_cm,
                             params, state)
        scene = BulletPhysics(bodies, GroundSpec()).worlds[0]  # one pybullet world, its own API
        for _ in range(500):
            poses = scene.read_poses()
            bank.step(poses, np.zeros(0), 1e-3, sk.MOTOR_PHYSICAL)
            if per_anchor:
                for i in range(len(geom.body_a)):
                    f = bank.string_force[i]
                    pb.applyExternalForce(scene.body_ids[geom.body_a[i]], -1, f.tolist(), bank.wa[i].tolist(),
                                          pb.WORLD_FRAME, physicsClientId=scene.client)
                    pb.applyExternalForce(scene.body_ids[geom.body_b[i]], -1, (-f).tolist(), bank.wb[i].tolist(),
                                          pb.WORLD_FRAME, physicsClientId=scene.client)
            else:
                scene.apply_wrenches(bank.force, bank.torque)
            scene.step()
        finals.append(scene.read_poses())
        scene.close()
    moved = np.abs(finals[0][:, :3] - bodies_com(bodies)).max()
    assert moved > 0.5  # the strings did real work in these 0.5 s
    # same wrench up to summation order; the lateral (mirror-symmetric) direction amplifies rounding
    assert np.abs(finals[0][:, :3] - finals[1][:, :3]).max() < 5e-3 * moved


def bodies_com(bodies) -> np.ndarray:
    return np.array([b.com_cm for b in bodies])
