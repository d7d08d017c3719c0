"""What a worker runs for one leased task: the run's trial config at the task's fidelity (a rung's
duration, engine, step and settle phase; a judge's finer step or other engine, perturbed on request;
an audit's exact re-run), and what it tells the coordinator about itself (the engines it can run, the
environment it runs on).

SPINEFARM_FAULT_DISTANCE_SCALE (fault injection for the audit tests and benchmarks): every distance
this worker reports is multiplied by it, as a mis-built or dishonest worker would report.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import os
import platform
from collections.abc import Callable
from typing import Any

from spinefarm.protocol.errors import ConfigError
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.work import TrialAssignment
from spinefarm.robot.profile import ground_friction

FAULT_SCALE_ENV = "SPINEFARM_FAULT_DISTANCE_SCALE"
_REPORTED_PACKAGES = ("numpy", "numba", "pybullet", "mujoco", "spinefarm")
POSE_JITTER_CM = 0.01
FRICTION_CHANGE = 0.1


def available_engines(only: tuple[str, ...] | None = None) -> tuple[str, ...]:
    """Engines this worker can run: their package is installed (and, given `only`, they are in it)."""
    from spinefarm.robot.engines import engine_names, engine_spec

    names = [n for n in engine_names() if only is None or n in only]
    return tuple(n for n in names if importlib.util.find_spec(engine_spec(n).package or n) is not None)


def parse_engines(text: str | None) -> tuple[str, ...] | None:
    """`--engines bullet,mujoco`: the engines a worker offers (None: every installed one)."""
    if text is None:
        return None
    from spinefarm.robot.engines import engine_names

    names = tuple(x.strip() for x in text.split(",") if x.strip())
    unknown = [n for n in names if n not in engine_names()]
    if not names or unknown:
        raise ConfigError("--engines names no known engine", received=text, expected=engine_names())
    return names


def environment() -> dict[str, str]:
    """What this worker computes with: python, platform, CPU model and the versions of the packages
    a result depends on (two machines whose results disagree differ somewhere here)."""
    from importlib.metadata import PackageNotFoundError, version

    env = {"python": platform.python_version(), "platform": platform.platform(terse=True)[:200],
           "cpu": _cpu_model()}
    for name in _REPORTED_PACKAGES:
        try:
            env[name] = version(name)
        except PackageNotFoundError:
            env[name] = "absent"
    return env


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()[:200]
    except OSError:
        pass
    return (platform.processor() or platform.machine())[:200]


def task_config(trial_config: Any, a: TrialAssignment) -> Any:
    """The run's TrialConfig at assignment `a`'s fidelity. Another engine than the run's starts from
    that engine's own settings (the run's engine options belong to the run's engine)."""
    cfg = trial_config if a.duration_s is None else dataclasses.replace(trial_config, duration_s=a.duration_s)
    f = a.fidelity
    if f is None:
        return cfg
    if f.engine is not None and f.engine != cfg.engine:
        cfg = dataclasses.replace(cfg, engine=f.engine, engine_options={})
    if f.dt_s is not None:
        cfg = dataclasses.replace(cfg, dt_s=f.dt_s, auto_dt=False)
    if f.settle_s is not None:
        cfg = dataclasses.replace(cfg, settle_s=f.settle_s)
    return cfg


def perturbed(cfg: Any, ground_friction: float) -> Any:
    """The judge's perturbed run: the start pose jittered, friction raised."""
    return dataclasses.replace(cfg, pose_jitter_cm=POSE_JITTER_CM,
                               ground_friction=ground_friction * (1 + FRICTION_CHANGE))


def with_fault(result: TrialResult) -> TrialResult:
    """The result as this worker reports it (see FAULT_SCALE_ENV)."""
    scale = os.environ.get(FAULT_SCALE_ENV)
    if not scale:
        return result
    k = float(scale)
    return dataclasses.replace(result, distance_m=result.distance_m * k, ntrt_distance_cm=result.ntrt_distance_cm * k,
                               speed_cm_s=result.speed_cm_s * k)


def physics_evaluator(morphology: Any, trial_config: Any, controller: str | None,
                      robust: dict | None = None, bodies: Any = None) -> Callable[[TrialAssignment], TrialResult]:
    """A function of one assignment: the trial at its fidelity (a rung, the judge, an audit), with the
    judge's perturbed run when asked. A missing engine package or an option the engine does not have fails
    here, not in every trial (a worker without the run's engine says so in its requests and is only given
    tasks in its engines). bodies: a co-designed run's robot.codesign.Bodies; each trial then runs its own
    body, checked first (worker.trial.feasibility)."""
    import numpy as np

    from spinefarm.worker.engines.base import engine_class
    from spinefarm.worker.trial.feasibility import FeasibilityCache, infeasible_result
    from spinefarm.worker.trial.setup import SetupCache
    from spinefarm.worker.trial.simulation import simulate

    if trial_config.engine in available_engines():
        engine_class(trial_config.engine).settings_from_options(trial_config.engine_options)
    setup = SetupCache()  # bodies, string tables, terrain and a resettable engine world, kept across trials
    from spinefarm.protocol.robust import RobustSpec

    spec = RobustSpec.from_dict(robust)
    base = morphology

    feasible = FeasibilityCache()

    def evaluate(a: TrialAssignment) -> TrialResult:
        cfg = task_config(trial_config, a)
        params = np.asarray(a.params_unit, dtype=float)
        if bodies is None:
            return _run(base, params, cfg, a)
        morphology, params = bodies.split(params)
        verdict = feasible.check(morphology, cfg.engine)
        r = _run(morphology, params, cfg, a) if verdict.ok else infeasible_result(verdict, a.seed)
        return dataclasses.replace(r, extras={**r.extras, "body_hash": morphology.spec_hash()})

    def _run(morphology: Any, params: Any, cfg: Any, a: TrialAssignment) -> TrialResult:
        if spec.active:  # K randomised episodes of this parameter set, at this task's fidelity (worker.trial.robust)
            from spinefarm.worker.trial.robust import run_episodes

            k = dataclasses.replace(spec, episodes=spec.episodes_for(a.duration_s), rung_episodes=(),
                                    rung_durations_s=())
            return with_fault(run_episodes(morphology, params, cfg, a.seed, k, controller=controller, setup=setup))
        # a rung's promotion goes on from the kept end of its last rung where this worker has it (the same bits)
        r = simulate(morphology, params, cfg, a.seed, controller=controller, setup=setup,
                     resume=not a.from_start).result
        if a.fidelity is not None and a.fidelity.perturb:
            friction = cfg.ground_friction if cfg.ground_friction is not None \
                else ground_friction(morphology, cfg.profile)
            p = simulate(morphology, params, perturbed(cfg, friction), a.seed, controller=controller).result
            r = dataclasses.replace(r, extras={**r.extras, "perturbed_distance_m": p.distance_m if p.ok else
                                               float("nan")})
        return with_fault(r)

    return evaluate
