"""Trials: `simulate` runs one, the one way to run a trial from Python (`simulate(...).result` is its
TrialResult); everything that runs trials (the worker, `spinefarm trial`, the tools) calls it.

simulate_batch is an internal detail of the trial core, not a second way in (left out of __all__): the world
axis simulate and a robust trial's episodes (worker.trial.robust) run on, imported elsewhere only by the tests
and the benchmark of that axis (bench/batch_worlds.py). simulate_batch(morphology, params, config, seeds, ...):
B parameter sets (or one repeated, e.g. the episodes of a robust evaluation) with one seed each (the seed
jitters world b's start pose by config.pose_jitter_cm); it returns one TrialOutcome per world, the same bits
as B calls of simulate. A world that diverges stops alone; a world its engine asks to run again in other
settings (MuJoCo's contact guard: BasePhysics.retries) is run again from its start, alone, and says so in its
result's extras.

The loop itself is worker.trial.loop (control law -> engine); phases and checks are worker.trial.batch; the
start pose, step, guards and score are worker.trial.episode.
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Mapping, Sequence

import numpy as np

from spinefarm.protocol.errors import ParameterError
from spinefarm.protocol.results import TrialResult
from spinefarm.robot.engines import engine_spec
from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.profile import apply_profile
from spinefarm.robot.spaces import param_space
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.control.law import ControlLaw, string_tables
from spinefarm.worker.engines.base import EngineFactory
from spinefarm.worker.trial.batch import Batch, Timing, Trajectory, WorldLog
from spinefarm.worker.trial.continued import end_key
from spinefarm.worker.trial.episode import EpisodeEnd, choose_step, score
from spinefarm.worker.trial.settled import settle_key
from spinefarm.worker.trial.setup import SetupCache, TrialSetup, setup_key

__all__ = ["Trajectory", "TrialConfig", "TrialOutcome", "choose_step", "random_unit_params", "simulate",
           "string_tables"]


@dataclasses.dataclass
class TrialOutcome:
    result: TrialResult
    trajectory: Trajectory | None
    com_path_cm: np.ndarray  # (n_checks, 3) robot COM at every guard check, for path comparisons
    com_path_time_s: np.ndarray  # (n_checks,) the times of those checks


def simulate(morphology: Morphology | str | Mapping, params: np.ndarray | Mapping[str, float] | list,
             config: TrialConfig | None = None, seed: int = 0, *, controller: str | None = None,
             scene_factory: EngineFactory | None = None, setup: TrialSetup | SetupCache | None = None,
             resume: bool = False) -> TrialOutcome:
    """Run one trial and return its result (`.result`, a TrialResult) with the recorded trajectory (if config
    asks for one). `morphology`: a built-in's name, a spec file's path, a spec mapping or a Morphology;
    `params`: a unit-cube vector of the controller space, or a mapping of named physical values. Divergence is a
    failed result, never an exception; bad parameters raise ParameterError.
    `scene_factory` replaces the configured engine's class (same constructor as BasePhysics).
    `setup`: a TrialSetup of this morphology and config, or a SetupCache, to reuse what earlier trials
    built (the result is the same bits either way). resume: go on from the kept end of an earlier, shorter trial of
    this parameter set in `setup` where there is one, and keep this trial's end (worker.trial.continued; the same
    bits as from the start; its result's extras say `continued_s`, the simulated seconds taken from that end)."""
    return simulate_batch(morphology, [params], config, [seed], controller=controller, scene_factory=scene_factory,
                          setup=setup, resume=resume)[0]


def simulate_batch(morphology: Morphology | str | Mapping, params: Sequence, config: TrialConfig | None = None,
                   seeds: Sequence[int] = (0,), *, controller: str | None = None,
                   scene_factory: EngineFactory | None = None, setup: TrialSetup | SetupCache | None = None,
                   resume: bool = False) -> list[TrialOutcome]:
    """B trials in one batch of worlds: params[b] (unit-cube vector or named physical values) with seeds[b];
    one TrialOutcome per world, each the same bits as simulate(morphology, params[b], config, seeds[b])."""
    cfg = config or TrialConfig()
    if len(params) != len(seeds) or not len(seeds):
        raise ParameterError("one seed per parameter set", received=f"{len(params)} sets, {len(seeds)} seeds",
                             expected="as many seeds as parameter sets, at least one")
    outcomes, retries = _simulate(morphology, list(params), cfg, list(seeds), controller, scene_factory, setup,
                                  resume)
    groups: dict[str, list[int]] = {}
    for b, (options, _) in retries.items():  # the engine's policy: again from the start, in other settings
        groups.setdefault(json.dumps(options, sort_keys=True), []).append(b)
    for options, worlds in groups.items():
        again = dataclasses.replace(cfg, engine_options={**cfg.engine_options, **json.loads(options)})
        rerun = simulate_batch(morphology, [params[b] for b in worlds], again, [seeds[b] for b in worlds],
                               controller=controller, scene_factory=scene_factory,
                               setup=None if isinstance(setup, TrialSetup) else setup, resume=resume)
        for b, out in zip(worlds, rerun, strict=True):
            out.result.extras.update(retries[b][1])
            outcomes[b] = out
    return outcomes


def _simulate(morphology: Morphology | str | Mapping, params: list, cfg: TrialConfig, seeds: list[int],
              controller: str | None, scene_factory: EngineFactory | None, setup: TrialSetup | SetupCache | None,
              resume: bool = False) -> tuple[list[TrialOutcome | None], dict]:
    t_wall = time.perf_counter()
    morph = apply_profile(load_morphology(morphology), cfg.profile)
    controller = controller or cfg.controller
    for seed in seeds:
        if not isinstance(seed, int | np.integer) or seed < 0:
            raise ParameterError("seed is not a whole number >= 0", received=seed, expected="an integer >= 0")
    if isinstance(setup, SetupCache):
        setup = setup.get(morph, cfg, controller)
    elif setup is None or setup.morph != morph or setup_key(setup.cfg) != setup_key(cfg) \
            or setup.controller != controller:
        setup = TrialSetup(morph, cfg, controller)
    space = setup.space
    physical = [space.param_space.physical(p) for p in params]
    networks = [space.network(x) for x in physical]
    geom = setup.geom
    law = ControlLaw(networks, [setup.string_tables(n) for n in networks],
                     (geom.body_a, geom.body_b, geom.anchor_a_cm, geom.anchor_b_cm), len(setup.bodies),
                     cfg.cpg_max_step_s, cfg.motor_model)
    timing = _timing(morph, cfg, setup.dt)
    offsets = [setup.start_offsets(int(s)) for s in seeds]
    scene, owned = setup.scene(None if offsets[0] is None else np.stack(offsets), scene_factory, len(seeds))
    key = _settle_key(setup, scene_factory, timing, law, offsets)
    end_at = _end_key(setup, scene_factory, timing, offsets, physical) if resume else None
    start = None if end_at is None else setup.rung_ends.get(end_at, timing.n_settle + timing.n_steps)
    try:
        batch = Batch(scene, law, timing, cfg, setup.masses, geom.start_length_cm, setup.terrain)
        worlds = batch.run(None if key is None or start is not None else setup.settled.get(key),
                           keep_settled=key is not None, resume=start, keep_end=end_at is not None)
        if key is not None and batch.settled is not None:
            setup.settled.put(key, batch.settled)
        if end_at is not None and batch.end is not None:
            setup.rung_ends.put(end_at, batch.end)
        retries = dict(scene.retries)
    finally:
        if owned:
            scene.close()
    wall_s = (time.perf_counter() - t_wall) / len(seeds)
    outcomes = [None if w.retry else _outcome(morph, setup, cfg, timing, w, int(s), wall_s)
                for w, s in zip(worlds, seeds, strict=True)]
    for out in outcomes if resume else ():  # only a one-world trial may have gone on from a kept end
        if out is not None:
            out.result.extras["continued_s"] = 0.0 if start is None else start.done * timing.dt_s
    return outcomes, retries


def _settle_key(setup: TrialSetup, scene_factory: EngineFactory | None, timing: Timing, law: ControlLaw,
                offsets: list) -> str | None:
    """The settle's key (worker.trial.settled) when this batch may start from a kept settle end: a settle phase, no
    recording, the set-up's own engine able to snapshot a world, and every world of the batch the same start
    pose and string tables."""
    if not timing.n_settle or timing.record_every or scene_factory is not None \
            or not engine_spec(setup.cfg.engine).can("snapshot"):
        return None
    keys = {settle_key(timing.n_settle, timing.check_every, o, law.params[b], law.state[b])
            for b, o in enumerate(offsets)}
    return keys.pop() if len(keys) == 1 else None


def _end_key(setup: TrialSetup, scene_factory: EngineFactory | None, timing: Timing, offsets: list,
             physical: list) -> str | None:
    """The key a one-world trial's end is kept under for a longer trial (worker.trial.continued), or None where it
    cannot go on from one: a batch of worlds, a recording, a replaced engine or one that cannot snapshot a world."""
    if len(physical) != 1 or timing.record_every or scene_factory is not None \
            or not engine_spec(setup.cfg.engine).can("snapshot"):
        return None
    return end_key(timing.n_settle, timing.check_every, timing.cpg_every, offsets[0], physical[0])


def _timing(morph: Morphology, cfg: TrialConfig, dt: float) -> Timing:
    duration = cfg.duration_s or morph.duration_s
    period = cfg.cpg_update_period_s or morph.control.cpg_update_period_s
    every = max(1, int(round(period / dt)))
    # the CPG at its own step only where no update interval above the physics step is fixed (NTRT's 0.1 s)
    own = cfg.cpg_own_step_s if every == 1 and cfg.cpg_update_period_s is None else None
    return Timing(n_settle=int(round(cfg.settle_s / dt)), n_steps=int(round(duration / dt)),
                  cpg_every=every, check_every=max(1, int(round(cfg.check_every_s / dt))),
                  record_every=None if cfg.record_every_s is None else max(1, int(round(cfg.record_every_s / dt))),
                  dt_s=dt, cpg_own_step_s=own)


def _outcome(morph: Morphology, setup: TrialSetup, cfg: TrialConfig, timing: Timing, w: WorldLog, seed: int,
             wall_s: float) -> TrialOutcome:
    n_settle, dt = timing.n_settle, timing.dt_s
    loco_steps = max(0, w.steps_done - n_settle) if w.settle_poses is not None else 0 if n_settle else w.steps_done
    extras = {"dt_s": dt, "engine": cfg.engine, "settle_s": n_settle * dt}
    # the start pose without jitter (or the pose after the settle): distances count from it
    measured = EpisodeEnd(w.end_poses, loco_steps, dt, w.end_work - w.settle_work, w.reason, w.settle_poses)
    result = score(morph, setup.masses, setup.build, measured, seed, wall_s, extras)
    path = np.array(w.com_path)
    return TrialOutcome(result, w.trajectory, path, np.arange(len(path)) * timing.check_every * dt)


def random_unit_params(morph: Morphology, seed: int, controller: str | None = None) -> np.ndarray:
    """A seeded uniform sample of the controller space's unit cube."""
    return np.random.default_rng(seed).random(len(param_space(morph, controller)))
