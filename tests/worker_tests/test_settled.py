"""The settled start (worker.trial.settled): a settle phase simulated once per set-up and start pose, every later
trial started from its end, gives what settling in every trial gives."""

from __future__ import annotations

import dataclasses

import pytest

from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.worker.trial.setup import SetupCache
from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, simulate, simulate_batch


def _same(a, b) -> None:
    assert abs(a.distance_m - b.distance_m) <= 1e-9, (a.distance_m, b.distance_m)
    assert a.distance_m == b.distance_m and a.work_j == b.work_j and a.cot == b.cot and a.status == b.status
    assert {k: v for k, v in a.extras.items()} == {k: v for k, v in b.extras.items()}


@pytest.mark.parametrize(("engine", "kept"), [("mujoco", True), ("bullet", False)])
def test_trials_started_from_a_kept_settle_match_trials_that_settle(engine, kept):
    """MuJoCo keeps the settle's end and starts later trials from it; Bullet settles in every trial (pybullet
    cannot put a world's contact state back exactly). Either way the distances are those of settling in the
    trial, within 1e-9 m (in fact the same bits)."""
    morph = load_morphology("tetraspine-ntrt")
    cfg = TrialConfig(duration_s=0.3, settle_s=0.3, engine=engine)
    cache = SetupCache()
    for seed in (1, 2, 3):
        u = random_unit_params(morph, seed)
        outcome = simulate(morph, u, cfg, seed, setup=cache)
        _same(outcome.result, simulate(morph, u, cfg, seed).result)
        assert outcome.com_path_cm.tolist() == simulate(morph, u, cfg, seed).com_path_cm.tolist()
    assert cache.get(morph, cfg, None).settled.hits == (2 if kept else 0)


def test_a_batch_starts_every_world_from_the_kept_settle():
    morph = load_morphology("tetraspine-ntrt")
    cfg = TrialConfig(duration_s=0.3, settle_s=0.3, engine="mujoco")
    cache = SetupCache()
    units = [random_unit_params(morph, s) for s in (4, 5, 6)]
    simulate(morph, units[0], cfg, 4, setup=cache)  # settles, keeps the end
    batch = simulate_batch(morph, units, cfg, [4, 5, 6], setup=cache)
    assert cache.get(morph, cfg, None).settled.hits == 1
    for u, seed, out in zip(units, (4, 5, 6), batch, strict=True):
        _same(out.result, simulate(morph, u, cfg, seed).result)


def test_what_a_settle_depends_on_is_not_shared():
    """Other start poses (a jittered start per seed), another settle length: each settles itself."""
    morph = load_morphology("tetraspine-ntrt")
    cache = SetupCache()
    jittered = TrialConfig(duration_s=0.2, settle_s=0.2, engine="mujoco", pose_jitter_cm=0.5)
    for seed in (1, 2):
        u = random_unit_params(morph, seed)
        _same(simulate(morph, u, jittered, seed, setup=cache).result, simulate(morph, u, jittered, seed).result)
    assert cache.get(morph, jittered, None).settled.hits == 0
    longer = dataclasses.replace(jittered, pose_jitter_cm=0.0)
    u = random_unit_params(morph, 3)
    simulate(morph, u, longer, 3, setup=cache)
    again = dataclasses.replace(longer, settle_s=0.3)
    _same(simulate(morph, u, again, 3, setup=cache).result, simulate(morph, u, again, 3).result)
    assert cache.get(morph, again, None).settled.hits == 0
