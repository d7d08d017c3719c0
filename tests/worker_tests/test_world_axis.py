"""The world axis: B worlds in one batch give the same bits as B single trials, on every engine; a world that
stops (diverges, or is handed back by its engine) leaves the others untouched."""

from __future__ import annotations

import numpy as np
import pytest

from spinefarm.protocol.results import TrialResult
from spinefarm.robot.bodies import build_bodies
from spinefarm.robot.engines import engine_names
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.scene import SceneConfig, build_terrain
from spinefarm.worker.engines.mujoco import MujocoPhysics, MujocoSettings
from spinefarm.worker.trial.loop import advance
from spinefarm.worker.trial.setup import SetupCache
from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, simulate, simulate_batch

SEEDS = [1, 2, 3, 4]


def _same(batch, singles) -> None:
    for one, alone in zip(batch, singles, strict=True):
        a, b = one.result.to_dict(), alone.result.to_dict()
        a.pop("wall_time_s"), b.pop("wall_time_s")
        assert a == b
        assert np.array_equal(one.com_path_cm, alone.com_path_cm)


# a speed guard that the start's drop trips in some of these worlds and not in others (measured)
GUARD_M_S = {"bullet": 0.41, "mujoco": 0.42}


@pytest.mark.parametrize("engine", engine_names())
def test_a_batch_of_worlds_is_the_bits_of_single_runs(engine):
    """Different parameter sets and seeds (start-pose jitter), and a speed guard that stops one world early."""
    m = load_morphology("tetraspine-ntrt")
    us = [random_unit_params(m, s) for s in SEEDS]
    us[3] = us[2]  # two episodes of one parameter set, seeds apart
    cfg = TrialConfig(duration_s=0.4, engine=engine, pose_jitter_cm=0.01, max_body_speed_m_s=GUARD_M_S[engine])
    batch = simulate_batch(m, us, cfg, SEEDS)
    _same(batch, [simulate(m, u, cfg, s) for u, s in zip(us, SEEDS, strict=True)])
    statuses = {o.result.status.value for o in batch}
    assert statuses == {"failed", "complete"}, [o.result.reason for o in batch]
    assert len({o.result.distance_m for o in batch}) == len(SEEDS)


@pytest.mark.parametrize("engine", engine_names())
def test_recorded_batches_and_reused_worlds_hold_the_same_bits(engine):
    """Recording goes step by step through the seam (MuJoCo otherwise runs compiled); a set-up cache keeps
    a resettable engine's worlds between batches."""
    m = load_morphology("tetraspine-ntrt")
    us = [random_unit_params(m, s) for s in SEEDS[:3]]
    cfg = TrialConfig(duration_s=0.3, engine=engine, pose_jitter_cm=0.01, record_every_s=0.05, settle_s=0.05)
    cache = SetupCache()
    batch = simulate_batch(m, us, cfg, SEEDS[:3], setup=cache)
    again = simulate_batch(m, us, cfg, SEEDS[:3], setup=cache)
    singles = [simulate(m, u, cfg, s) for u, s in zip(us, SEEDS[:3], strict=True)]
    _same(batch, singles)
    _same(again, singles)
    for one, alone in zip(batch, singles, strict=True):
        for key, values in one.trajectory.arrays().items():
            assert np.array_equal(values, alone.trajectory.arrays()[key]), key
    fast = simulate_batch(m, us, TrialConfig(duration_s=0.3, engine=engine, pose_jitter_cm=0.01, settle_s=0.05),
                          SEEDS[:3])
    assert [o.result.distance_m for o in fast] == [o.result.distance_m for o in batch]


def test_the_engine_hands_back_a_world_its_contact_guard_cannot_vouch_for():
    """MuJoCo's policy (segment_contacts "auto"): a world where a left-out contact could form within a step
    leaves the batch for `retries`, with the settings to run it again in; the other world runs on."""
    bodies = build_bodies(load_morphology("tetraspine-ntrt").structure)
    scene = MujocoPhysics(bodies, build_terrain(SceneConfig(), 0.5, (0, 0)), 1e-3, MujocoSettings(), n_worlds=2)
    scene.qvel[1][1, :3] = [0.0, 0.0, -1e5]  # world 1: segment 1 flying at segment 0
    active = np.ones(2, dtype=bool)
    ran = []

    def run(k: int, act: np.ndarray) -> None:  # the loop's steps, here without a control law
        ran.append((k, act.copy()))
        for _ in range(k):
            scene.step(act)
    advance(scene, run, 10, active, 10)
    assert active.tolist() == [True, False]
    options, extras = scene.retries[1]
    assert options == {"segment_contacts": "scene"} and extras["segment_contacts"].startswith("modelled: gap")
    assert sum(k for k, _ in ran) == 10 and all(a.tolist() == [True, False] for _, a in ran)
    scene.close()


def test_one_seed_per_parameter_set():
    m = load_morphology("tetraspine-ntrt")
    with pytest.raises(ValueError, match="one seed per parameter set"):
        simulate_batch(m, [random_unit_params(m, 1)] * 2, TrialConfig(duration_s=0.1), [1])


def test_worlds_handed_back_are_run_again_with_the_engines_settings():
    """The ribbed spine's ribs start 2 mm apart: with segment_contacts "auto" MuJoCo hands every world back,
    and the batch runs them again with the contacts: the bits of modelling them throughout."""
    m = load_morphology("ribbed")
    us = [random_unit_params(m, s) for s in SEEDS[:2]]
    auto = TrialConfig(duration_s=0.2, engine="mujoco", pose_jitter_cm=0.01)
    scene = TrialConfig(duration_s=0.2, engine="mujoco", pose_jitter_cm=0.01,
                        engine_options={"segment_contacts": "scene"})
    batch = simulate_batch(m, us, auto, SEEDS[:2])
    singles = [simulate(m, u, scene, s) for u, s in zip(us, SEEDS[:2], strict=True)]
    for one, alone in zip(batch, singles, strict=True):
        assert one.result.distance_m == alone.result.distance_m and one.result.work_j == alone.result.work_j
        assert one.result.extras["segment_contacts"].startswith("modelled: gap")
        # the note fits the protocol: the coordinator takes the result as it is (a longer one was refused)
        assert TrialResult.from_dict(one.result.to_dict()).extras == one.result.extras
