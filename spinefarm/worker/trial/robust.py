"""A robust trial: one parameter set run in K randomised worlds (protocol.robust), one result with every
episode attached and the medians of their parts.

Episodes are independent worlds. They run through `run_worlds`, the one place that loops over them,
so running them as one batch of worlds is a change there alone.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import NamedTuple

import numpy as np

from spinefarm.protocol.columns import SCORE_NAMES
from spinefarm.protocol.measured import measured_numbers
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.robust import EpisodeDraw, EpisodeResult, RobustSpec, draw_episode
from spinefarm.protocol.states import TrialStatus
from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.morphology.variants import with_density_factor
from spinefarm.robot.profile import apply_profile, engine_only
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.trial.setup import SetupCache
from spinefarm.worker.trial.simulation import simulate_batch


class EpisodeWorld(NamedTuple):
    """One episode's world: its draw (and seed), the morphology (masses drawn) and the trial config
    (friction, jitter, scene)."""

    draw: EpisodeDraw
    morph: Morphology
    config: TrialConfig


def episode_world(morph: Morphology, cfg: TrialConfig, draw: EpisodeDraw) -> EpisodeWorld:
    """The world of one draw: friction x friction_scale (of the scene's, the config's or the robot's), rod
    density x mass_scale, the draw's start jitter, and rough ground seeded by the draw when asked."""
    morph = apply_profile(morph, cfg.profile)  # scaled below: the worlds' configs keep its engine constants only
    base = cfg.scene.friction if cfg.scene.friction is not None else \
        cfg.ground_friction if cfg.ground_friction is not None else morph.ground_friction
    scene = dataclasses.replace(cfg.scene, friction=None)
    if draw.rough_seed >= 0:
        scene = dataclasses.replace(scene, kind="rough", rough_seed=draw.rough_seed)
    config = dataclasses.replace(cfg, ground_friction=base * draw.friction_scale, scene=scene,
                                 profile=engine_only(cfg.profile),
                                 pose_jitter_cm=draw.start_jitter_cm or cfg.pose_jitter_cm)
    world_morph = morph if draw.mass_scale == 1.0 else with_density_factor(morph, draw.mass_scale)
    return EpisodeWorld(draw, world_morph, config)


def run_worlds(worlds: Sequence[EpisodeWorld], params: np.ndarray | Mapping[str, float], controller: str | None,
               setup: SetupCache | None = None) -> list[TrialResult]:
    """One result per world, in order (each world seeded by its draw). Worlds that share a morphology and a
    trial config (they differ only in their seeds: start jitter alone is randomised) run as one batch of
    worlds (worker.trial.simulation.simulate_batch); a drawn friction or mass makes each world a batch of its own."""
    groups: dict[tuple[Morphology, str], list[int]] = {}
    for i, w in enumerate(worlds):
        groups.setdefault((w.morph, w.config.config_hash()), []).append(i)
    out: list[TrialResult | None] = [None] * len(worlds)
    for members in groups.values():
        first = worlds[members[0]]
        batch = simulate_batch(first.morph, [params] * len(members), first.config,
                               [worlds[i].draw.seed for i in members], controller=controller, setup=setup)
        for i, outcome in zip(members, batch, strict=True):
            out[i] = outcome.result
    return out  # type: ignore[return-value]


def run_episodes(morph: Morphology, params: np.ndarray | Mapping[str, float], cfg: TrialConfig, trial_seed: int,
                 spec: RobustSpec, *, controller: str | None = None, setup: SetupCache | None = None) -> TrialResult:
    """The trial of `params` over spec.episodes randomised worlds: a result whose parts are the episodes'
    medians and whose `episodes` holds each; failed when any episode failed (the first failure's reason)."""
    draws = [draw_episode(spec, trial_seed, k) for k in range(spec.episodes)]
    results = run_worlds([episode_world(morph, cfg, d) for d in draws], params, controller, setup)
    return combine(results, draws, trial_seed)


def combine(results: Sequence[TrialResult], draws: Sequence[EpisodeDraw], trial_seed: int) -> TrialResult:
    """Episodes -> one TrialResult (medians of the complete episodes' parts, of all when none completed)."""
    episodes = tuple(_episode(r, d) for r, d in zip(results, draws, strict=True))
    failed = [(d.episode, r) for r, d in zip(results, draws, strict=True) if not r.ok]
    pool = [r for r in results if r.ok] or list(results)
    parts = {name: float(np.median([getattr(r, name) for r in pool])) for name in SCORE_NAMES}
    parts["wall_time_s"] = float(sum(r.wall_time_s for r in results))
    reason = f"episode {failed[0][0]} of {len(results)}: {failed[0][1].reason}"[:150] if failed else ""
    extras = {**results[0].extras, "episodes": len(results)}
    return TrialResult(TrialStatus.FAILED if failed else TrialStatus.COMPLETE, reason, seed=int(trial_seed),
                       extras=extras, episodes=episodes, **parts)


def _episode(r: TrialResult, d: EpisodeDraw) -> EpisodeResult:
    return EpisodeResult(episode=d.episode, seed=d.seed, status="complete" if r.ok else "failed",
                         reason=r.reason[:160], **measured_numbers(r),
                         friction_scale=d.friction_scale, mass_scale=d.mass_scale,
                         start_jitter_cm=d.start_jitter_cm, rough_seed=d.rough_seed)

