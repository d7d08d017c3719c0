"""What every trial of one run builds alike, built once: the controller space, bodies, string geometry,
string tables, terrain, start pose, step, and (for engines that can reset exactly) the engine world itself.

A worker running many trials of one run keeps a SetupCache keyed by the morphology, the trial config's
hash and the controller; a trial then only resets what it changes (string state, CPG, engine state).
Reuse never changes a result: a reused MuJoCo world is reset to the state a fresh one starts in, and
Bullet worlds (whose contact caches a reset would not clear) are built fresh every trial.
"""

from __future__ import annotations

import dataclasses
from collections import OrderedDict
from typing import Any

import numpy as np

from spinefarm.robot.bodies import build_bodies, build_strings
from spinefarm.robot.cpg_network import CpgNetwork
from spinefarm.robot.engines import engine_spec
from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.profile import engine_options
from spinefarm.robot.reach import reachable_rod_pairs
from spinefarm.robot.scene import build_terrain
from spinefarm.robot.spaces import controller_space
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.control.law import string_tables
from spinefarm.worker.engines.base import BasePhysics, EngineFactory, engine_class
from spinefarm.worker.trial.continued import RungEnds
from spinefarm.worker.trial.episode import build_poses, choose_step, start_lift_cm, start_rotation
from spinefarm.worker.trial.settled import SettledStarts


class TrialSetup:
    """The parameter- and seed-independent part of a trial of `morph` under `cfg` (controller given)."""

    def __init__(self, morph: Morphology, cfg: TrialConfig, controller: str | None) -> None:
        self.morph, self.cfg, self.controller = morph, cfg, controller
        self.space = controller_space(morph, controller)  # built once: 1-5 ms for the NTRT spaces
        self.engine_cls = engine_class(cfg.engine)
        self.settings = self.engine_cls.settings_from_options({**engine_options(cfg.profile, cfg.engine),
                                                               **cfg.engine_options})
        self.bodies = build_bodies(morph.structure)
        self.geom = build_strings(morph.structure, self.bodies, cfg.relocate_anchors)
        self.masses = np.array([b.mass_kg for b in self.bodies])
        self.dt = choose_step(morph, cfg)
        nodes = morph.structure.node_array()
        friction = cfg.ground_friction if cfg.ground_friction is not None else morph.ground_friction
        self.terrain = build_terrain(cfg.scene, friction, (float(nodes[:, 2].min()), float(nodes[:, 2].max())))
        self.rotation = start_rotation(cfg.scene)
        self.lift = start_lift_cm(self.terrain, morph, self.rotation)
        self.build = build_poses(self.bodies, self.lift, self.rotation)  # distances count from this pose
        self._string_tables = string_tables
        self._tables: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}
        self._scene: BasePhysics | None = None
        self.scenes_built = 0
        self._rod_pairs: np.ndarray | None = None
        self.settled = SettledStarts()  # settle ends kept for later trials (worker.trial.settled)
        self.rung_ends = RungEnds()  # trial ends kept for longer trials of a set (worker.trial.continued)

    def string_tables(self, network: CpgNetwork) -> tuple[np.ndarray, np.ndarray]:
        """Fresh copies of the packed string parameters and initial state for this network's node map."""
        key = np.asarray(network.node_string, dtype=np.int64).tobytes()
        if key not in self._tables:
            node_of_string = {int(s): n for n, s in enumerate(network.node_string)}
            self._tables[key] = self._string_tables(self.morph, self.geom.start_length_cm, node_of_string)
        params, state = self._tables[key]
        return params.copy(), state.copy()

    def start_offsets(self, seed: int) -> np.ndarray | None:
        """Per-body start offsets (cm): the seeded pose jitter plus the lift clear of the terrain."""
        rng = np.random.default_rng(seed)
        offsets = rng.normal(0.0, self.cfg.pose_jitter_cm, (len(self.bodies), 3)) \
            if self.cfg.pose_jitter_cm > 0 else None
        if self.lift > 0:
            offsets = np.zeros((len(self.bodies), 3)) if offsets is None else offsets
            offsets[:, 1] += self.lift
        return offsets

    def scene(self, offsets: np.ndarray | None, factory: EngineFactory | None = None, n_worlds: int = 1
              ) -> tuple[BasePhysics, bool]:
        """(n_worlds engine worlds at the start pose, offsets (n_worlds, nb, 3) or None; whether the caller owns
        them and must close them). An engine that can reset keeps its worlds for the next call of as many."""
        args = (self.bodies, self.terrain, self.dt, self.settings, offsets, self.rotation)
        kwargs: dict[str, Any] = {"n_worlds": n_worlds}
        if factory is None and self.engine_cls.wants_rod_pairs(self.settings):
            kwargs["rod_pairs"] = self.rod_pairs()  # computed once per set-up
        if factory is not None or not engine_spec(self.cfg.engine).can("reset"):
            self.scenes_built += 1
            return (factory or self.engine_cls)(*args, **kwargs), True
        if self._scene is not None and self._scene.n_worlds != n_worlds:
            self.close()
        if self._scene is None:
            self.scenes_built += 1
            self._scene = self.engine_cls(*args, **kwargs)
        else:
            self._scene.reset(offsets)
        return self._scene, False

    def rod_pairs(self) -> np.ndarray:
        """(p, 4) rows (body a, rod of a, body b, rod of b): the rod pairs that can come within reach
        (robot.reach), before the scene's collision filter."""
        if self._rod_pairs is None:
            n = len(self.bodies)
            self._rod_pairs = reachable_rod_pairs(self.morph.structure, self.bodies, self.geom,
                                                  [(a, b) for a in range(n) for b in range(a + 1, n)])
        return self._rod_pairs

    def close(self) -> None:
        if self._scene is not None:
            self._scene.close()
            self._scene = None


# fields a set-up does not depend on: trials differing only in these (the rungs of a multi-fidelity
# search: other durations, settle phases) share one set-up
PER_TRIAL_FIELDS = ("duration_s", "settle_s", "record_every_s", "check_every_s", "extras")


def setup_key(cfg: TrialConfig) -> str:
    return dataclasses.replace(cfg, **{f: TrialConfig.__dataclass_fields__[f].default if f != "extras" else {}
                                       for f in PER_TRIAL_FIELDS}).config_hash()


class SetupCache:
    """TrialSetups by (morphology, trial config hash without the per-trial fields, controller); keeps the most
    recent `size`."""

    def __init__(self, size: int = 4) -> None:
        self.size = size
        self._items: OrderedDict[Any, TrialSetup] = OrderedDict()

    def get(self, morph: Morphology, cfg: TrialConfig, controller: str | None) -> TrialSetup:
        key = (morph, setup_key(cfg), controller)
        if key in self._items:
            self._items.move_to_end(key)
            return self._items[key]
        setup = self._items[key] = TrialSetup(morph, cfg, controller)
        while len(self._items) > self.size:
            self._items.popitem(last=False)[1].close()
        return setup

    def close(self) -> None:
        for setup in self._items.values():
            setup.close()
        self._items.clear()
