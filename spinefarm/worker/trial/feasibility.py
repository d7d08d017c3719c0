"""A sampled body's feasibility, checked before any trial of it runs (docs/codesign.md): it builds, no rod
passes through another segment's, its strings can hold their pretension (robot.morphology.bodycheck); then a
short passive run (the CPG at rest, as the contract's settle) takes stable steps, finds a rest shape and keeps
every joint held by a string in tension. A body that fails is a failed trial whose reason starts with
`infeasible:`; nothing raises, so a worker never dies of a body.

The verdict depends on the body and the engine only, so it is kept per body hash (FeasibilityCache).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spinefarm.protocol.errors import ConfigError, SpinefarmError
from spinefarm.protocol.results import TrialResult
from spinefarm.robot.bodies import build_bodies
from spinefarm.robot.engines import DEFAULT_ENGINE
from spinefarm.robot.morphology.bodycheck import static_problem
from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.spaces import param_space
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.trial.lru import LRU

INFEASIBLE = "infeasible: "
SETTLE_S = 2.0  # passive seconds: the built-ins reach rest (< 0.2 cm/s) well within them
REST_SPEED_CM_S = 1.5  # the contract's "at rest" (worker.tools.contract.check_passive_settle)


@dataclass(frozen=True)
class Feasibility:
    """ok, or the reason a body cannot be searched (one line, without the `infeasible: ` prefix)."""

    ok: bool
    reason: str = ""


def passive_params(morph: Morphology, seed: int = 1) -> np.ndarray:
    """A seeded random parameter vector (unit cube) with every CPG amplitude at its smallest value."""
    space = param_space(morph)
    physical = space.from_unit(np.random.default_rng(seed).random(len(space)))
    amplitude = [i for i, n in enumerate(space.names) if "amplitude" in n]
    for i in amplitude:
        physical[i] = max(0.0, space.lows[i])
    return space.to_unit(physical)


def step_config(morph: Morphology, engine: str, **kw) -> TrialConfig:
    """The default step, or the automatic one for a structure known to be unstable at it."""
    from spinefarm.worker.trial.episode import choose_step

    try:
        cfg = TrialConfig(engine=engine, **kw)
        choose_step(morph, cfg)
        return cfg
    except ConfigError:
        return TrialConfig(engine=engine, auto_dt=True, **kw)


def _passive_problem(morph: Morphology, engine: str, settle_s: float) -> str | None:
    from spinefarm.worker.trial.simulation import simulate

    cfg = step_config(morph, engine, duration_s=settle_s, record_every_s=settle_s / 20)
    out = simulate(morph, passive_params(morph), cfg, 0)
    if not out.result.ok:
        return f"no stable step: {out.result.reason}"
    a = out.trajectory.arrays()
    masses = np.array([b.mass_kg for b in build_bodies(morph.structure)])
    com = (a["poses"][:, :, :3] * masses[None, :, None]).sum(axis=1) / masses.sum()
    speed = float(np.linalg.norm(com[-1] - com[-5]) / (a["time_s"][-1] - a["time_s"][-5]))
    if speed >= REST_SPEED_CM_S:
        return f"no rest shape: still moving at {speed:.3g} cm/s after {settle_s:g} s (at rest: < {REST_SPEED_CM_S})"
    joint = np.asarray(morph.joint_of_string())
    tension = a["tension_n"][-1]
    loose = [k for k in range(morph.structure.n_segments - 1) if not (tension[joint == k] > 0.0).any()]
    if loose:
        return (f"strings slack: no string of joint {loose[0]} is in tension at rest "
                f"({len(loose)} of {morph.structure.n_segments - 1} joints held by none)")
    return None


def check_body(morph: Morphology, engine: str = DEFAULT_ENGINE, settle_s: float = SETTLE_S) -> Feasibility:
    """Whether this body may be searched, and if not why; never raises for a bad body."""
    try:
        why = static_problem(morph.structure) or _passive_problem(morph, engine, settle_s)
    except (SpinefarmError, FloatingPointError, ValueError) as exc:  # a body the engine or law refuses
        why = f"does not build: {exc}"
    return Feasibility(why is None, why or "")


def infeasible_result(verdict: Feasibility, seed: int, trial_id: int = -1) -> TrialResult:
    """The failed trial a body that cannot be searched stands for."""
    return TrialResult.failed(INFEASIBLE + verdict.reason, seed, trial_id)


class FeasibilityCache:
    """Verdicts by (body hash, engine), the most recent `size` kept (worker.trial.lru): every trial of a body after
    its first costs a lookup. `checked`: the bodies checked so far."""

    def __init__(self, size: int = 256) -> None:
        self._verdicts: LRU[tuple[str, str], Feasibility] = LRU(size, "kept feasibility verdicts")

    @property
    def checked(self) -> int:
        return self._verdicts.misses

    def check(self, morph: Morphology, engine: str = DEFAULT_ENGINE) -> Feasibility:
        key = (morph.spec_hash(), engine)
        verdict = self._verdicts.get(key)
        if verdict is None:
            verdict = check_body(morph, engine)
            self._verdicts.put(key, verdict)
        return verdict
