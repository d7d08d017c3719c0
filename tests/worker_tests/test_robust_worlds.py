"""A robust trial's episode worlds: batched where they share a config, the bits of single runs either way."""

from __future__ import annotations

from spinefarm.protocol.robust import RobustSpec, draw_episode
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.worker.trial.robust import episode_world, run_episodes
from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, simulate


def singles(morph, u, cfg, spec, seed):
    out = []
    for k in range(spec.episodes):
        w = episode_world(morph, cfg, draw_episode(spec, seed, k))
        out.append(simulate(w.morph, u, w.config, w.draw.seed).result.distance_m)
    return out


def test_episodes_give_the_bits_of_single_runs_batched_or_not():
    morph = load_morphology("tetraspine")
    u = random_unit_params(morph, 3)
    cfg = TrialConfig(duration_s=0.3)
    jitter = RobustSpec(3, {"start_jitter_cm": 0.5})  # one config: a batch of 3 worlds
    r = run_episodes(morph, u, cfg, 11, jitter)
    assert [e.distance_m for e in r.episodes] == singles(morph, u, cfg, jitter, 11)
    assert len({e.distance_m for e in r.episodes}) == 3  # three different worlds
    drawn = RobustSpec(2, {"friction": 0.1, "mass": 0.05})  # every world its own config
    r = run_episodes(morph, u, cfg, 11, drawn)
    assert [e.distance_m for e in r.episodes] == singles(morph, u, cfg, drawn, 11)
    assert r.distance_m == sorted(e.distance_m for e in r.episodes)[0] / 2 + sorted(
        e.distance_m for e in r.episodes)[1] / 2  # the median of two
