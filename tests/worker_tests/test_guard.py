"""The guard check's compiled fast path says "sane" only where the exact check finds nothing, and a trial's
decisions and bits are those of the exact check alone."""

from __future__ import annotations

import numpy as np
import pytest

from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.scene import SceneConfig, build_terrain
from spinefarm.worker.sim import strings as sk
from spinefarm.worker.trial import guard
from spinefarm.worker.trial.episode import STRETCH_BASE_MIN_CM, check_state
from spinefarm.worker.trial.setup import SetupCache
from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, simulate


def _state(seed: int):
    m = load_morphology("tetraspine-ntrt")
    cfg = TrialConfig(duration_s=0.3, engine="mujoco")
    cache = SetupCache()
    out = simulate(m, random_unit_params(m, seed), cfg, seed, setup=cache)
    setup = cache.get(m, cfg, None)
    net = setup.space.network(setup.space.param_space.physical(random_unit_params(m, seed)))
    _, sstate = setup.string_tables(net)
    poses = setup._scene.read_poses()[0].copy()
    return m, cfg, setup, poses, sstate, out


def test_the_fast_path_is_sane_only_where_the_exact_check_finds_nothing():
    _, cfg, setup, poses, sstate, _ = _state(1)
    rng = np.random.default_rng(5)
    boxes, limits = guard.level_boxes(setup.terrain), guard.limits(cfg)
    base = np.maximum(setup.geom.start_length_cm, STRETCH_BASE_MIN_CM)
    fast_sane = exact_fail = 0
    for k in range(400):
        p, s = poses.copy(), sstate.copy()
        p[:, 1] += rng.normal(0, 8)  # heights (about 0.11 m) across the limits set below
        last = p[:, :3] - rng.normal(0, 0.15, (len(p), 3))  # body speeds around the 0.4 m/s limit set below
        s[:, sk.S_LPREV] *= rng.uniform(0.5, 1.6)  # stretch across the limit below (start lengths 24-28 cm)
        if k % 50 == 0:
            p[k % len(p), 3] = np.nan
        tight = TrialConfig(max_body_speed_m_s=0.4, min_height_m=-0.1, max_height_m=0.2, max_stretch_ratio=1.3,
                            max_kinetic_energy_j=0.25)  # three 2.46 kg segments
        exact = check_state(p, last, setup.masses, s, setup.geom.start_length_cm, 0.01, tight, setup.terrain)
        fast = guard.clearly_sane(p, last, setup.masses, s[:, sk.S_LPREV], base, 0.01, boxes, guard.limits(tight))
        assert not (fast and exact), exact
        fast_sane += fast
        exact_fail += bool(exact)
    assert fast_sane > 50 and exact_fail > 50  # both sides of the limits were reached
    assert limits[0] == cfg.max_body_speed_m_s


def test_off_the_boxes_or_on_a_heightfield_or_slope_the_exact_check_decides():
    _, _, setup, poses, sstate, _ = _state(2)
    boxes = guard.level_boxes(setup.terrain)
    far = poses.copy()
    far[:, 0] += 1e6  # beyond the ground's edge
    base = np.maximum(setup.geom.start_length_cm, STRETCH_BASE_MIN_CM)
    assert not guard.clearly_sane(far, far[:, :3], setup.masses, sstate[:, sk.S_LPREV], base, 0.01, boxes,
                                  guard.limits(TrialConfig()))
    for kind in ("rough", "slope"):
        assert guard.level_boxes(build_terrain(SceneConfig(kind=kind, slope_deg=5.0), 1.0, (-50.0, 50.0))) is None
    assert guard.level_boxes(build_terrain(SceneConfig(kind="obstacles"), 1.0, (-50.0, 50.0))).shape[0] > 1


@pytest.mark.parametrize("speed_guard_m_s", [5.0, 0.42])  # the default, and one the start's drop trips in some
def test_a_trial_has_the_bits_and_reason_of_the_exact_check_alone(monkeypatch, speed_guard_m_s):
    m = load_morphology("tetraspine-ntrt")
    cfg = TrialConfig(duration_s=0.4, engine="mujoco", pose_jitter_cm=0.01, max_body_speed_m_s=speed_guard_m_s)
    fast = [simulate(m, random_unit_params(m, s), cfg, s) for s in (1, 2, 3, 4)]
    monkeypatch.setattr(guard, "level_boxes", lambda terrain: None)
    exact = [simulate(m, random_unit_params(m, s), cfg, s) for s in (1, 2, 3, 4)]
    for a, b in zip(fast, exact, strict=True):
        assert a.result.reason == b.result.reason and a.result.distance_m == b.result.distance_m
        assert np.array_equal(a.com_path_cm, b.com_path_cm)
    if speed_guard_m_s < 1:
        assert any(o.result.reason for o in exact)


def test_a_sane_check_keeps_the_com_bits_of_scoring_and_an_unclear_one_writes_nothing():
    from spinefarm.worker.trial import scoring

    rng = np.random.default_rng(11)
    boxes = np.array([[0.0, 0.0, 1e6, 1e6, 0.0]])  # one level ground box, top at 0 cm
    limits = guard.limits(TrialConfig())
    for nb in (3, 12, 17, 40):  # below and above numpy's 8-wide pairwise blocks
        for _ in range(50):
            masses = rng.uniform(0.05, 3.0, nb)
            poses = np.column_stack([rng.uniform(-500, 500, nb), rng.uniform(5, 10, nb), rng.uniform(-500, 500, nb),
                                     np.zeros((nb, 3)), np.ones(nb)])
            strings = np.ones((4, 3))  # string state, column 1 the lengths: a stretch of 1 (limit 2)
            last, good, com = poses[:, :3] + 1e-4, np.zeros((nb, 7)), np.full(3, np.nan)
            assert guard.check_clear(poses, last, good, masses, float(masses.sum()), strings, 1, np.ones(4), 0.01,
                                     boxes, limits, com)
            assert np.array_equal(com, scoring.robot_com_cm(poses, masses))
            assert np.array_equal(last, poses[:, :3]) and np.array_equal(good, poses)
    poses[0, 1] = -50.0  # a segment below the ground: not clearly sane, the exact check decides
    last, good, com = poses[:, :3] + 1e-4, np.zeros((nb, 7)), np.full(3, np.nan)
    assert not guard.check_clear(poses, last, good, masses, float(masses.sum()), strings, 1, np.ones(4), 0.01, boxes,
                                 limits, com)
    assert np.isnan(com).all() and not good.any() and np.array_equal(last, poses[:, :3] + 1e-4)
