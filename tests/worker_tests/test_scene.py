"""Scenes: terrain geometry agrees with the engine, the robot starts clear of it, filters apply."""

from __future__ import annotations

import numpy as np
import pybullet as pb
import pytest

from spinefarm.protocol.errors import ConfigError
from spinefarm.protocol.states import TrialStatus
from spinefarm.robot.bodies import build_bodies
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.scene import SceneConfig, build_terrain, pairs_off, surface_height_cm
from spinefarm.worker.engines.bullet import BulletPhysics
from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, simulate


def engine_surface(terrain, xs, zs) -> np.ndarray:
    scene = BulletPhysics([], terrain).worlds[0]  # one pybullet world, its own API
    try:
        starts = [[x, 200.0, z] for x, z in zip(xs, zs, strict=True)]
        ends = [[x, -200.0, z] for x, z in zip(xs, zs, strict=True)]
        hits = pb.rayTestBatch(starts, ends, physicsClientId=scene.client)
        return np.array([h[3][1] for h in hits])
    finally:
        scene.close()


@pytest.mark.parametrize("cfg", [SceneConfig(), SceneConfig(kind="slope", slope_deg=10.0),
                                 SceneConfig(kind="rough", rough_amplitude_cm=3.0, rough_seed=4),
                                 SceneConfig(kind="obstacles", obstacle_spacing_cm=40.0)])
def test_terrain_heights_agree_with_the_engine(cfg):
    terrain = build_terrain(cfg, 0.5, (-50.0, 50.0))
    rng = np.random.default_rng(0)
    xs, zs = rng.uniform(-200, 200, 40), rng.uniform(-200, 200, 40)
    ours = surface_height_cm(terrain, xs, zs)
    theirs = engine_surface(terrain, xs, zs)
    if cfg.kind == "rough":
        # ours bounds the interpolated surface from above by at most the local relief
        assert np.all(ours >= theirs - 1e-6)
        assert np.max(ours - theirs) < 2 * cfg.rough_amplitude_cm
        assert np.ptp(theirs) > cfg.rough_amplitude_cm  # really rough
    else:
        assert np.allclose(ours, theirs, atol=1e-6)


def test_rough_ground_is_seeded():
    a = build_terrain(SceneConfig(kind="rough", rough_seed=1), 0.5, (0, 0)).heightfield.heights_cm
    b = build_terrain(SceneConfig(kind="rough", rough_seed=1), 0.5, (0, 0)).heightfield.heights_cm
    c = build_terrain(SceneConfig(kind="rough", rough_seed=2), 0.5, (0, 0)).heightfield.heights_cm
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_obstacles_stay_clear_of_the_start_pose():
    terrain = build_terrain(SceneConfig(kind="obstacles", obstacle_spacing_cm=30.0), 0.5, (-243.0, 100.0))
    bars = terrain.boxes[1:]
    assert bars and all(not (-243.0 - b.half_extents_cm[2] < b.centre_cm[2] < 100.0 + b.half_extents_cm[2])
                        for b in bars)


def test_collision_filter_pairs():
    assert pairs_off(build_terrain(SceneConfig(), 0.5, (0, 0)), 4) == []
    auto_flat = build_terrain(SceneConfig(collision_filter="auto"), 0.5, (0, 0))
    assert pairs_off(auto_flat, 4) == [(0, 2), (0, 3), (1, 3)]
    assert pairs_off(build_terrain(SceneConfig(kind="rough", collision_filter="auto"), 0.5, (0, 0)), 4) == []


def test_filtered_pairs_pass_through_each_other_in_the_engine():
    bodies = build_bodies(load_morphology("tetraspine-ntrt").structure)
    terrain = build_terrain(SceneConfig(collision_filter="neighbours"), 0.5, (0, 0))
    scene = BulletPhysics(bodies, terrain).worlds[0]
    try:
        ids = scene.body_ids
        pb.resetBasePositionAndOrientation(ids[2], bodies[0].com_cm.tolist(), [0, 0, 0, 1],
                                           physicsClientId=scene.client)  # overlap segments 0 and 2
        pb.performCollisionDetection(physicsClientId=scene.client)
        assert not pb.getContactPoints(ids[0], ids[2], physicsClientId=scene.client)
        pb.resetBasePositionAndOrientation(ids[1], bodies[0].com_cm.tolist(), [0, 0, 0, 1],
                                           physicsClientId=scene.client)  # neighbours still collide
        pb.performCollisionDetection(physicsClientId=scene.client)
        assert pb.getContactPoints(ids[0], ids[1], physicsClientId=scene.client)
    finally:
        scene.close()


def test_robot_slides_down_a_steep_slippery_slope():
    morph = load_morphology("tetraspine-ntrt")
    u = random_unit_params(morph, 1)
    u[1] = 0.0
    scene = SceneConfig(kind="slope", slope_deg=25.0, friction=0.1)  # tan 25 deg = 0.47 > 0.1 effective
    r = simulate(morph, u, TrialConfig(duration_s=1.0, scene=scene), 1).result
    assert r.status == TrialStatus.COMPLETE, r.reason
    assert r.distance_m > 0.5  # slid more than half a metre in a second (downhill is +z)


def test_every_scene_runs_and_is_recorded_in_the_config():
    morph = load_morphology("tetraspine-ntrt")
    u = random_unit_params(morph, 2)
    for cfg in (SceneConfig(kind="rough", rough_amplitude_cm=1.0), SceneConfig(kind="obstacles")):
        tc = TrialConfig(duration_s=0.3, scene=cfg)
        assert simulate(morph, u, tc, 2).result.status == TrialStatus.COMPLETE
        assert TrialConfig.from_dict(tc.to_dict()) == tc
        assert tc.to_dict()["scene"]["kind"] == cfg.kind


def test_bad_scene_values_are_named():
    with pytest.raises(ConfigError, match="scene kind"):
        SceneConfig(kind="lava")
    with pytest.raises(ConfigError, match=r"scene\.slope_deg"):
        SceneConfig(kind="slope", slope_deg=80)
    with pytest.raises(ConfigError, match="unknown scene fields"):
        TrialConfig.from_dict({"scene": {"kind": "flat", "gravity": 1}})


def test_scene_from_the_command_line_and_into_the_run_file(tmp_path):
    from spinefarm.coordinator.problem import build_run_config
    from spinefarm.coordinator.setup import SearchSettings, new_run
    from spinefarm.protocol.settings import JudgePolicy
    from spinefarm.robot.scene import parse_scene
    from spinefarm.storage.hdf5_reader import read_meta

    scene = parse_scene("rough, rough_amplitude_cm=3, rough_seed=7, collision_filter=auto")
    assert scene["kind"] == "rough" and scene["rough_amplitude_cm"] == 3.0 and scene["rough_seed"] == 7
    with pytest.raises(ConfigError, match="bad scene field"):
        parse_scene("slope,angle=3")
    with pytest.raises(ConfigError, match="not a number"):
        parse_scene("slope,slope_deg=steep")
    config = build_run_config("scene-run", "tetraspine-ntrt", duration_s=0.2, trial_overrides={"scene": scene})
    _, storage = new_run(config, SearchSettings(trials=1, judge=JudgePolicy(enabled=False)), tmp_path / "run.h5")
    storage.close()
    stored = read_meta(tmp_path / "run.h5").trial_config["scene"]
    assert stored == scene  # the HDF5 file records the scene its trials ran on
    assert TrialConfig.from_dict(read_meta(tmp_path / "run.h5").trial_config).scene.kind == "rough"


def test_a_robot_off_the_grounds_edge_is_told_so_and_a_larger_ground_keeps_it_on():
    """NTRT's ground is a 10 m square; a gait that reaches its edge falls, and the reason says so (not a
    divergence) with the scene field that makes a larger one."""
    morph = load_morphology("tetraspine-ntrt")
    u = random_unit_params(morph, 1)
    small = TrialConfig(duration_s=1.0, scene=SceneConfig(ground_half_extent_cm=10.0))  # narrower than the robot
    r = simulate(morph, u, small, 1).result
    assert r.status == TrialStatus.FAILED
    assert r.reason.startswith("fell off the ground's edge: segment "), r.reason
    assert "half width of 10 cm" in r.reason and "--scene flat,ground_half_extent_cm=" in r.reason
    ntrt = TrialConfig(duration_s=1.0)
    assert simulate(morph, u, ntrt, 1).result.status == TrialStatus.COMPLETE
    # NTRT's size is the default and is left out of stored configs, so their hashes are those from before the field
    explicit = TrialConfig(duration_s=1.0, scene=SceneConfig(ground_half_extent_cm=500.0))
    assert "ground_half_extent_cm" not in ntrt.to_dict()["scene"] and explicit.config_hash() == ntrt.config_hash()
    large = TrialConfig(duration_s=1.0, scene=SceneConfig(ground_half_extent_cm=1000.0))
    assert TrialConfig.from_dict(large.to_dict()) == large and large.config_hash() != ntrt.config_hash()
    with pytest.raises(ConfigError, match=r"scene\.ground_half_extent_cm"):
        SceneConfig(ground_half_extent_cm=1.0)
