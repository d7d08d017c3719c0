"""One robust episode's world as docs/results.md's robust scoring draws it, checked field by field without a
simulator: friction x friction_scale of the scene's, else the config's, else the robot's; rod density x
mass_scale; the draw's start jitter; rough ground seeded by the draw when it has a rough seed (0 included)."""

from __future__ import annotations

import dataclasses

import pytest

from spinefarm.protocol.robust import EpisodeDraw, RobustSpec, draw_episode
from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.scene import SceneConfig
from spinefarm.worker.trial.robust import episode_world
from spinefarm.worker.trial.simulation import TrialConfig


@pytest.fixture(scope="module")
def morph():
    m = load_morphology("tetraspine")
    return dataclasses.replace(m, ground_friction=0.8)   # distinct from every friction below


def densities(m) -> list[float]:
    return [mat.density_kg_per_cm3 for _, mat in m.structure.rod_materials]


@pytest.mark.parametrize(("scene_mu", "config_mu", "expected"), [(0.5, 0.7, 0.5 * 1.5), (None, 0.7, 0.7 * 1.5),
                                                                 (None, None, 0.8 * 1.5)])
def test_the_drawn_friction_scales_the_scenes_else_the_configs_else_the_robots(morph, scene_mu, config_mu,
                                                                                expected) -> None:
    cfg = TrialConfig(duration_s=1.0, ground_friction=config_mu, scene=SceneConfig(friction=scene_mu))
    w = episode_world(morph, cfg, EpisodeDraw(0, 11, friction_scale=1.5))
    assert w.config.ground_friction == pytest.approx(expected)
    assert w.config.scene.friction is None      # one friction in the world: the drawn one


def test_the_drawn_mass_scales_every_rods_density_and_one_keeps_the_robot(morph) -> None:
    cfg = TrialConfig(duration_s=1.0)
    for scale in (1.25, 2.0, 0.5):
        heavy = episode_world(morph, cfg, EpisodeDraw(0, 11, mass_scale=scale))
        assert densities(heavy.morph) == pytest.approx([d * scale for d in densities(morph)])
    same = episode_world(morph, cfg, EpisodeDraw(1, 12))
    assert densities(same.morph) == densities(morph)
    assert same.config.ground_friction == pytest.approx(0.8) and same.draw == EpisodeDraw(1, 12)


def test_the_draws_jitter_replaces_the_configs_and_none_keeps_it(morph) -> None:
    cfg = TrialConfig(duration_s=1.0, pose_jitter_cm=0.3)
    assert episode_world(morph, cfg, EpisodeDraw(0, 11, start_jitter_cm=2.5)).config.pose_jitter_cm == 2.5
    assert episode_world(morph, cfg, EpisodeDraw(0, 11)).config.pose_jitter_cm == 0.3


@pytest.mark.parametrize("rough_seed", [0, 7])
def test_a_rough_seed_makes_the_ground_rough_with_that_seed(morph, rough_seed: int) -> None:
    cfg = TrialConfig(duration_s=1.0, scene=SceneConfig(kind="slope", slope_deg=5.0))
    w = episode_world(morph, cfg, EpisodeDraw(0, 11, rough_seed=rough_seed))
    assert (w.config.scene.kind, w.config.scene.rough_seed) == ("rough", rough_seed)
    own = episode_world(morph, cfg, EpisodeDraw(0, 11))     # -1: the run's own scene
    assert (own.config.scene.kind, own.config.scene.slope_deg) == ("slope", 5.0)


def test_episode_zero_of_a_stored_robust_block_is_its_first_draw(morph) -> None:
    cfg = TrialConfig(duration_s=1.0, ground_friction=1.0)
    robust = {"episodes": 3, "randomize": {"friction": 0.5, "mass": 0.2}}
    zero = draw_episode(RobustSpec.from_dict(robust), 42, 0)          # episode 0 of protocol.robust's draws
    w = episode_world(morph, cfg, zero)
    again = episode_world(Morphology.from_dict(morph.to_dict()), cfg, zero)   # the robot as a run file stores it
    assert w.config == again.config and densities(w.morph) == densities(again.morph)
    c, m = w.config, w.morph
    assert c.ground_friction == pytest.approx(zero.friction_scale)
    # drawn, not the run's own: friction within 1 +- 0.5 of 1.0, masses within 1 +- 0.2, and not both unchanged
    assert 0.5 <= c.ground_friction <= 1.5
    ratio = densities(m)[0] / densities(morph)[0]
    assert 0.8 <= ratio <= 1.2
    assert (c.ground_friction, ratio) != (1.0, 1.0)
