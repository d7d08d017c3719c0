"""The physics seam: a backend builds a world of rigid segments on a terrain and steps it.

A backend knows nothing of strings, CPGs or scoring. The trial loop calls, per trial:
  __init__(bodies, terrain, dt_s, settings, ...)   once: build the world at the start pose
  read_poses()                                     before every step: (n_bodies, 7) COM cm + quaternion x, y, z, w
  apply_wrenches(force, torque)                    once per step: net force (n_bodies, 3) kg*cm/s^2 at the COM
                                                   and torque (n_bodies, 3) kg*cm^2/s^2 about it, world frame,
                                                   held for the next step only
  step()                                           advance dt_s
  close()                                          free the world (also via `with`)

Optional, used when a backend has them (the contract above is all a backend must provide):
  reset(start_offsets_cm)                          back to the start pose at rest, the same state as a fresh
                                                   world (lets a worker keep one world per run: worker.setup)
  fused_stepper(bank, cpg, cpg_every, motor_mode)  an object whose run(n0, n1) -> (status, step reached) does
                                                   steps n0..n1-1 of the loop (read, CPG when due, strings,
                                                   wrench, step) in compiled code, bit-identical to the loop
                                                   through the methods above; the trial uses it unless recording
  velocities(), set_velocity(i, linear, angular)   world-frame body velocities, for checks and tests

Engine knobs (solver, contacts, friction combination, workarounds) live in each backend's settings
dataclass, built from TrialConfig.engine_options by `settings_from_options`, never in morphology data.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import fields
from typing import Any, ClassVar

import numpy as np
from spinefarm.protocol.errors import ConfigError
from spinefarm.robot.bodies import BodyModel
from spinefarm.robot.scene import Terrain

GRAVITY_CM_S2 = 981.0


class BasePhysics:
    """One world of rigid segments. Units: cm, kg, s; Y is up; gravity -981 cm/s^2."""

    name: ClassVar[str] = ""
    settings_type: ClassVar[type] = object

    def __init__(self, bodies: list[BodyModel], terrain: Terrain, dt_s: float, settings: Any = None,
                 start_offsets_cm: np.ndarray | None = None,
                 start_rotation: tuple[float, float, float, float] | None = None,
                 collision_pairs_off: list[tuple[int, int]] | None = None) -> None:
        raise NotImplementedError

    def read_poses(self) -> np.ndarray:
        raise NotImplementedError

    def apply_wrenches(self, force: np.ndarray, torque: np.ndarray) -> None:
        raise NotImplementedError

    def step(self) -> None:
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> BasePhysics:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @classmethod
    def settings_from_options(cls, options: Mapping[str, Any] | None) -> Any:
        """The backend's frozen settings from {field: value}; unknown fields name the allowed ones."""
        known = {f.name for f in fields(cls.settings_type)}
        unknown = sorted(set(options or {}) - known)
        if unknown:
            raise ConfigError(f"unknown {cls.name} engine options", received=unknown, expected=sorted(known))
        return cls.settings_type(**dict(options or {}))


# name -> (module, class name): backends are imported only when used, so one engine's package
# need not be installed to run another
_ENGINES: dict[str, tuple[str, str]] = {
    "bullet": ("spinefarm.worker.engines.bullet", "BulletPhysics"),
    "mujoco": ("spinefarm.worker.engines.mujoco", "MujocoPhysics"),
}


def register_engine(name: str, module: str, class_name: str) -> None:
    _ENGINES[name] = (module, class_name)


def engine_names() -> list[str]:
    return sorted(_ENGINES)


def engine_class(name: str) -> type[BasePhysics]:
    if name not in _ENGINES:
        raise ConfigError("unknown engine", received=name, expected=engine_names())
    import importlib

    module, cls = _ENGINES[name]
    try:
        return getattr(importlib.import_module(module), cls)
    except ImportError as exc:
        raise ConfigError(f"engine {name!r} is not installed", received=str(exc),
                          expected=f"the package {name} needs (pip install 'spinefarm[worker]')") from exc


EngineFactory = Callable[..., BasePhysics]
