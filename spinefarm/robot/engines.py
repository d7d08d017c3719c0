"""The physics engines as data: names, where each backend lives, its default step, its typed settings
(the `--engine-option` keys: type, allowed values or range, default) and its declared optional abilities.

Engine-free (no simulator is imported here), so a coordinator validates a run's engine and options before it
writes anything, and the CLI offers the names. Adding an engine is its module under worker/engines/ plus one
EngineSpec in ENGINES. A backend's settings dataclass has exactly the fields declared here, with the same
defaults (a test holds them together); the backend may check more (e.g. relations between fields).

Abilities (what the trial loop may use beyond BasePhysics' required methods):
  reset          back to the start pose at rest, bit-identical to a fresh world (a worker keeps one world per run)
  velocities     velocities() / set_velocity(), for checks and tests
  compiled_step  compiled_worlds(): each world's state and wrench arrays and a C step function, so the loop
                 can run many steps in one compiled call (worker.trial.loop)
  snapshot       snapshot(world) / restore(world, state): a world's whole state, put back into any world of the
                 same model so that it goes on in the same bits (a settled start, worker.trial.settled)
  set_state      set_state(world, poses, velocities): every body's pose and velocity written at once, e.g. a
                 recorded state a fit's window starts from (worker.fit)
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from spinefarm.protocol.errors import ConfigError

ABILITIES = frozenset({"reset", "velocities", "compiled_step", "snapshot", "set_state"})
DEFAULT_ENGINE = "bullet"  # the judge: a trial config without an engine runs here


@dataclass(frozen=True)
class EngineOption:
    """One setting of an engine. kind: bool, int, float, str or tuple (of `length` floats); choices: the allowed
    strings; low/high: the allowed range of a number (inclusive)."""

    name: str
    kind: type
    default: Any
    choices: tuple[str, ...] = ()
    low: float | None = None
    high: float | None = None
    length: int = 0

    def allowed(self) -> str:
        if self.choices:
            return f"one of {list(self.choices)}"
        if self.kind is bool:
            return "true or false"
        if self.kind is tuple:
            return f"{self.length} numbers"
        lo = "-inf" if self.low is None else f"{self.low:g}"
        hi = "inf" if self.high is None else f"{self.high:g}"
        return f"{'an integer' if self.kind is int else 'a number'} in [{lo}, {hi}]"

    def check(self, engine: str, value: Any) -> None:
        """Raise ConfigError naming the engine, this option, the value and what is allowed."""
        if not self._ok(value):
            raise ConfigError(f"{engine} engine option {self.name}: value not allowed", received=value,
                              expected=self.allowed())

    def _ok(self, value: Any) -> bool:
        if self.kind is bool:
            return isinstance(value, bool)
        if self.kind is str:
            return isinstance(value, str) and (not self.choices or value in self.choices)
        if self.kind is tuple:
            return isinstance(value, list | tuple) and len(value) == self.length and all(
                _is_number(v) for v in value)
        if not _is_number(value) or (self.kind is int and not isinstance(value, int)):
            return False
        return (self.low is None or value >= self.low) and (self.high is None or value <= self.high)


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


@dataclass(frozen=True)
class EngineSpec:
    """An engine: its backend class (module, class name), default physics step, settings and abilities."""

    name: str
    module: str
    class_name: str
    default_dt_s: float
    options: tuple[EngineOption, ...]
    abilities: frozenset[str] = field(default_factory=frozenset)
    summary: str = ""
    package: str = ""  # the Python package the backend needs (looked for without importing it)
    # the CPG's own step where the spec updates it every physics step (TrialConfig.cpg_step_s); None: every step
    default_cpg_step_s: float | None = None

    def option(self, name: str) -> EngineOption:
        for o in self.options:
            if o.name == name:
                return o
        raise ConfigError(f"unknown {self.name} engine option {name!r}", received=name,
                          expected=f"one of {self.option_names()}")

    def option_names(self) -> list[str]:
        return sorted(o.name for o in self.options)

    def defaults(self) -> dict[str, Any]:
        return {o.name: o.default for o in self.options}

    def can(self, ability: str) -> bool:
        if ability not in ABILITIES:
            raise ConfigError("unknown engine ability", received=ability, expected=sorted(ABILITIES))
        return ability in self.abilities


_F, _I, _B, _S = float, int, bool, str
_GRAVITY = EngineOption("gravity_cm_s2", _F, 981.0, low=0.0)

ENGINES: dict[str, EngineSpec] = {spec.name: spec for spec in (
    EngineSpec("bullet", "spinefarm.worker.engines.bullet", "BulletPhysics", 1e-3, (
        EngineOption("solver_iterations", _I, 10, low=1, high=1000),
        EngineOption("erp", _F, 0.2, low=0.0, high=1.0),
        EngineOption("split_impulse", _B, True),
        EngineOption("split_impulse_threshold", _F, -0.04),
        EngineOption("warm_starting_factor", _F, 0.85, low=0.0, high=1.0),
        EngineOption("cone_friction", _B, False),
        _GRAVITY,
        EngineOption("friction_anchor", _B, True),
        EngineOption("constraint_solver", _S, "sequential_impulse", choices=("sequential_impulse", "mlcp_dantzig")),
    ), frozenset({"velocities", "set_state"}), "pybullet, the judge: hard contacts, 1 ms default step", "pybullet"),
    EngineSpec("mujoco", "spinefarm.worker.engines.mujoco", "MujocoPhysics", 1e-3, (
        EngineOption("integrator", _S, "implicitfast", choices=("euler", "implicit", "implicitfast", "rk4")),
        EngineOption("cone", _S, "elliptic", choices=("pyramidal", "elliptic")),
        EngineOption("solver", _S, "newton", choices=("newton", "cg", "pgs")),
        EngineOption("iterations", _I, 100, low=1, high=10_000),
        EngineOption("ls_iterations", _I, 50, low=1, high=10_000),
        EngineOption("tolerance", _F, 1e-8, low=0.0, high=1.0),
        EngineOption("solref_time_s", _F, 0.005, low=0.0, high=1.0),
        EngineOption("solref_damping_ratio", _F, 1.0, low=0.0, high=100.0),
        EngineOption("solimp", tuple, (0.9, 0.95, 0.001, 0.5, 2.0), length=5),
        EngineOption("contact_geometry", _S, "auto", choices=("auto", "ends", "capsules", "cylinders")),
        EngineOption("segment_contacts", _S, "auto", choices=("auto", "scene", "off", "reach")),
        EngineOption("islands", _B, False),
        EngineOption("noslip_iterations", _I, 0, low=0, high=10_000),
        EngineOption("margin_cm", _F, 0.0, low=0.0, high=10.0),
        _GRAVITY,
    ), frozenset({"reset", "velocities", "compiled_step", "snapshot", "set_state"}),
        "MuJoCo, the fast screen: soft contacts",
        # the CPG at its own step up to 4 ms (bench/cpg_step.py: within docs/accuracy.md's bar)
        "mujoco", default_cpg_step_s=0.004),
)}


def engine_names() -> list[str]:
    return sorted(ENGINES)


def engine_spec(name: str) -> EngineSpec:
    """The registered engine `name`; a one-line error naming the registered ones otherwise."""
    spec = ENGINES.get(name) if isinstance(name, str) else None
    if spec is None:
        raise ConfigError("unknown engine", received=name, expected=f"one of {engine_names()}")
    return spec


def check_engine_options(name: str, options: Mapping[str, Any] | None) -> None:
    """Raise ConfigError (one line: the option, what was given, what is allowed) unless every option is a
    setting of engine `name` with an allowed value. Run before anything is written or built."""
    spec = engine_spec(name)
    for key, value in (options or {}).items():
        spec.option(key).check(name, value)
