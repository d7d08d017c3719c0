"""The physics seam: a backend builds B worlds of rigid segments on a terrain and steps them.

A backend knows nothing of strings, CPGs or scoring: it is handed one net wrench per body and world. The
trial loop (worker.trial.loop) calls, per batch of trials:
  __init__(bodies, terrain, dt_s, settings, start_offsets_cm, start_rotation, collision_pairs_off, n_worlds)
                                  once: build B worlds at the start pose (start_offsets_cm (B, nb, 3) per world,
                                  or (nb, 3) / None for one world; n_worlds given alone: B worlds, no offsets)
  read_poses()                    before every step: (B, nb, 7) COM cm + quaternion x, y, z, w
  apply_wrenches(force, torque, active)
                                  once per step: net force (B, nb, 3) kg*cm/s^2 at the COM and torque (B, nb, 3)
                                  kg*cm^2/s^2 about it, world frame, held for the next step only
  step(active)                    advance dt_s; active (B,) bool or None (all): worlds not active may be skipped
                                  (a CPU backend loops over its worlds; a batched one may step them all)
  steps_ahead(active, n_steps, horizon_steps)
                                  the engine's policy over a run of steps, asked by the loop before each piece
                                  and once after the last (n_steps: those left): how many the active worlds
                                  may run now (by default all); an engine may shorten the piece, or take a world
                                  out of `active` and put it in `retries` with the settings it must be run again
                                  in (from its start). It is told nothing back: it reads its worlds' state.
  close()                         free the worlds (also via `with`)
An engine whose wants_rod_pairs(settings) is true is also given rod_pairs=(p, 4) rows (body a, rod of a, body b,
rod of b): the rod pairs of different segments that can come within reach of each other (robot.reach), so it
may test only those.
Attributes every backend sets in __init__: n_worlds, n_bodies, dt_s, and retries = {} (world -> (engine options,
result extras) of a world to run again; emptied by reset()).

Optional abilities, declared in the engine's registry entry (spinefarm.robot.engines), never guessed:
  reset(start_offsets_cm)         "reset": back to the start pose at rest, the same state as fresh worlds
  velocities(), set_velocity()    "velocities": world-frame body velocities, for checks and tests
  snapshot(world), restore(world, state)
                                  "snapshot": a world's whole state, and putting it back into a world of the same
                                  model, which then goes on in the same bits (worker.trial.settled)
  set_state(world, poses, velocities)
                                  "set_state": every body's pose (nb, 7) COM cm + quaternion x, y, z, w and
                                  velocity (nb, 6) cm/s and rad/s, world frame, one write per body
  compiled_worlds()               "compiled_step": per world (address of a C function void step(uint64 model,
                                  uint64 data), model address, data address, state (nb, k), pose_columns (7,)
                                  int64, wrench (nb, 6)), for the compiled loop of worker.trial.loop;
                                  with compiled_look(world): its steps_ahead policy as data the compiled loop
                                  applies between steps (None: it never shortens a run)

Engine knobs (solver, contacts, friction combination, workarounds) live in each backend's settings
dataclass, built from TrialConfig.engine_options by `settings_from_options`, never in morphology data.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar

import numpy as np

from spinefarm.protocol.errors import ConfigError
from spinefarm.robot.bodies import BodyModel
from spinefarm.robot.engines import check_engine_options, engine_spec
from spinefarm.robot.scene import Terrain

GRAVITY_CM_S2 = 981.0

Vector3 = Sequence[float] | np.ndarray


class BasePhysics:
    """One world of rigid segments. Units: cm, kg, s; Y is up; gravity -981 cm/s^2."""

    name: ClassVar[str] = ""
    settings_type: ClassVar[type] = object
    n_worlds: int = 1
    n_bodies: int = 0
    dt_s: float = 1e-3
    retries: dict[int, tuple[dict[str, Any], dict[str, str]]]  # world -> (engine options, result extras)

    def __init__(self, bodies: list[BodyModel], terrain: Terrain, dt_s: float, settings: Any = None,
                 start_offsets_cm: np.ndarray | None = None,
                 start_rotation: tuple[float, float, float, float] | None = None,
                 collision_pairs_off: list[tuple[int, int]] | None = None, n_worlds: int | None = None) -> None:
        raise NotImplementedError

    def read_poses(self) -> np.ndarray:
        raise NotImplementedError

    def apply_wrenches(self, force: np.ndarray, torque: np.ndarray, active: np.ndarray | None = None) -> None:
        raise NotImplementedError

    def step(self, active: np.ndarray | None = None) -> None:
        raise NotImplementedError

    @staticmethod
    def wants_rod_pairs(settings: Any) -> bool:
        """Whether the constructor wants rod_pairs (robot.reach) with these settings."""
        return False

    def steps_ahead(self, active: np.ndarray, n_steps: int, horizon_steps: int) -> int:
        """How many of the next n_steps the active worlds may run now; see the module docstring."""
        return n_steps

    def close(self) -> None:
        raise NotImplementedError

    # optional abilities: a backend overrides these only if its registry entry declares them
    def reset(self, start_offsets_cm: np.ndarray | None = None) -> None:
        """ability "reset": back to the start pose at rest, the same state as a fresh world."""
        raise NotImplementedError(f"engine {self.name} has no reset")

    def velocities(self) -> np.ndarray:
        """ability "velocities": (B, nb, 6) world-frame body velocities, linear cm/s and angular rad/s."""
        raise NotImplementedError(f"engine {self.name} has no velocities")

    def set_velocity(self, index: int, linear_cm_s: Vector3, angular_rad_s: Vector3 = (0.0, 0.0, 0.0),
                     world: int = 0) -> None:
        """ability "velocities": set one body's world-frame velocity."""
        raise NotImplementedError(f"engine {self.name} has no set_velocity")

    def snapshot(self, world: int) -> Any:
        """ability "snapshot": world `world`'s whole state (opaque; for restore on this engine's model)."""
        raise NotImplementedError(f"engine {self.name} has no snapshot")

    def restore(self, world: int, state: Any) -> None:
        """ability "snapshot": world `world` takes a state from snapshot()."""
        raise NotImplementedError(f"engine {self.name} has no restore")

    def set_state(self, world: int, poses: np.ndarray, velocities: np.ndarray) -> None:
        """ability "set_state": world `world`'s bodies at poses (nb, 7) COM cm + quaternion (x, y, z, w) with
        velocities (nb, 6) linear cm/s and angular rad/s, world frame."""
        raise NotImplementedError(f"engine {self.name} has no set_state")

    def compiled_worlds(self) -> list[tuple]:
        """ability "compiled_step": each world's (step function address, model address, data address, state,
        pose_columns, wrench); see the module docstring."""
        raise NotImplementedError(f"engine {self.name} has no compiled step")

    def compiled_look(self, world: int) -> tuple | None:
        """ability "compiled_step": world `world`'s steps_ahead policy as data for the compiled loop, or None
        when steps_ahead never shortens a run; an engine whose policy has no compiled form raises."""
        if type(self).steps_ahead is not BasePhysics.steps_ahead:
            raise NotImplementedError(f"engine {self.name} has a steps_ahead policy and no compiled_look")
        return None

    def __enter__(self) -> BasePhysics:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @classmethod
    def settings_from_options(cls, options: Mapping[str, Any] | None) -> Any:
        """The backend's frozen settings from {field: value}, checked against the registry first (unknown
        options name the allowed ones)."""
        check_engine_options(cls.name, options)
        return cls.settings_type(**dict(options or {}))


def engine_class(name: str) -> type[BasePhysics]:
    """The backend class of a registered engine (spinefarm.robot.engines), imported only when used, so one
    engine's package need not be installed to run another."""
    import importlib

    spec = engine_spec(name)
    try:
        return getattr(importlib.import_module(spec.module), spec.class_name)
    except ImportError as exc:
        if spec.package == "pybullet" and sys.version_info >= (3, 12):  # the worker extra leaves it out there
            raise ConfigError(
                f"engine {name!r} needs pybullet, which publishes wheels up to Python 3.11 only (this is "
                f"{sys.version_info.major}.{sys.version_info.minor})", received=str(exc),
                expected="--engine mujoco here, or a Python 3.11 environment for Bullet") from exc
        raise ConfigError(f"engine {name!r} is not installed", received=str(exc),
                          expected=f"the package {name} needs (pip install 'spinefarm[worker]')") from exc


def world_offsets(start_offsets_cm: np.ndarray | None, n_worlds: int | None, n_bodies: int
                  ) -> list[np.ndarray | None]:
    """Per-world start offsets from the constructor's arguments: (B, nb, 3) -> B worlds, (nb, 3) -> one,
    None -> n_worlds (default 1) worlds without offsets."""
    if start_offsets_cm is None:
        return [None] * (n_worlds or 1)
    offsets = np.asarray(start_offsets_cm, dtype=float)
    if offsets.ndim == 2:
        offsets = offsets[None]
    if offsets.shape[1:] != (n_bodies, 3) or (n_worlds is not None and offsets.shape[0] != n_worlds):
        raise ConfigError("start offsets do not fit the worlds", received=offsets.shape,
                          expected=f"({n_worlds or 'B'}, {n_bodies}, 3)")
    return list(offsets)


EngineFactory = Callable[..., BasePhysics]
