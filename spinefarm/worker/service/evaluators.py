"""Evaluators: a run's config turned into a function of one leased trial (physics, or the test objective)."""

from __future__ import annotations

import os
import re
import signal
import time
from collections.abc import Callable

import numpy as np

from spinefarm.protocol.errors import RunMismatchError
from spinefarm.protocol.params import ParamSpace
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.run import RunConfig
from spinefarm.protocol.states import TrialStatus
from spinefarm.protocol.work import TrialAssignment
from spinefarm.robot.spaces import param_space
from spinefarm.worker.service.assignment import physics_evaluator, with_fault

Evaluator = Callable[[TrialAssignment], TrialResult | None]  # None: abandoned (the worker is stopping)


def sphere_result(space: ParamSpace, a: TrialAssignment, delay_s: float = 0.0) -> TrialResult:
    """The built-in test objective: no physics, a smooth bowl with its top at x_i = 0.3.

    delay_s: wall time the trial takes (sleeping), to stand in for a physics trial in fault tests.
    """
    t0 = time.perf_counter()
    x = space.from_unit(np.asarray(a.params_unit))
    if delay_s > 0:
        time.sleep(delay_s)
    distance_m = float(len(x) - np.sum((x - 0.3) ** 2))
    work_j = float(np.sum(x**2))
    return TrialResult(TrialStatus.COMPLETE, "", distance_m, 100.0 * distance_m, 10.0 * distance_m, work_j,
                       work_j / (9.81 * distance_m) if distance_m > 0 else float("inf"), 10.0,
                       time.perf_counter() - t0, 1.0, a.seed)


def _poison_bands(spec: object) -> dict[str, tuple[float, float]]:
    """The test objective's fault bands, {"hang": [lo, hi], "crash": [lo, hi]} on the first unit parameter:
    a trial there hangs (sleeps for ever) or crashes its process (SIGSEGV), for fault tests and the soak."""
    if spec is None:
        return {}
    ok = isinstance(spec, dict) and set(spec) <= {"hang", "crash"} and all(
        isinstance(v, list | tuple) and len(v) == 2 and all(isinstance(x, int | float) for x in v)
        for v in spec.values())
    if not ok:
        raise RunMismatchError("bad poison bands of the test objective", received=repr(spec)[:80],
                               expected='{"hang": [lo, hi], "crash": [lo, hi]} on the first unit parameter')
    return {k: (float(v[0]), float(v[1])) for k, v in spec.items()}


def _poisoned(bands: dict[str, tuple[float, float]], a: TrialAssignment) -> None:
    u0 = a.params_unit[0] if a.params_unit else -1.0
    if "crash" in bands and bands["crash"][0] <= u0 < bands["crash"][1]:
        os.kill(os.getpid(), signal.SIGSEGV)
    if "hang" in bands and bands["hang"][0] <= u0 < bands["hang"][1]:
        while True:
            time.sleep(3600.0)


def build_evaluator(config: RunConfig) -> Evaluator:
    """Turn a run object into a function of one assignment. The robot, its parameter space and the
    trial config are built from the run's own data (never looked up by name) and must reproduce the
    run's hashes; otherwise RunMismatchError says which part differs."""
    space = config.space()
    if config.is_test_objective:  # the test objective, see coordinator.problem
        if re.fullmatch(r"sphere(:\d+)?", config.morphology) is None:
            raise RunMismatchError("run has no morphology spec", received=config.morphology,
                                   expected="a morphology spec, or the test objective sphere[:N]")
        delay_s = float(config.trial_config.get("duration_s") or 0.0)
        poison = _poison_bands(config.trial_config.get("poison"))

        def sphere(a: TrialAssignment) -> TrialResult:
            _poisoned(poison, a)
            return with_fault(sphere_result(space, a, delay_s if a.duration_s is None else a.duration_s))

        return sphere
    if config.fit:  # a model fit's run: a trial is one candidate's loss over its recordings
        from spinefarm.worker.fit.task import fit_evaluator

        return fit_evaluator(config)
    from spinefarm.robot.morphology.model import Morphology
    from spinefarm.worker.trial.simulation import TrialConfig

    morphology = Morphology.from_dict(config.morphology_spec)
    trial_config = TrialConfig.from_dict(config.trial_config)
    space = param_space(morphology, config.controller)
    bodies = None
    if config.body:  # a co-designed run: the body's constants follow the gait's parameters
        from spinefarm.robot.codesign import Bodies, BodySearch

        search = BodySearch.from_dict(config.body)
        space = search.space(space)
        bodies = Bodies(search, space)
    built = {"spec_hash": morphology.spec_hash(), "space_hash": space.space_hash(),
             "trial_config_hash": trial_config.config_hash()}
    for name, value in built.items():
        if getattr(config, name) != value:
            raise RunMismatchError(f"this worker cannot reproduce the run's {name} (a different software "
                                   "version?)", received=value, expected=getattr(config, name))
    return physics_evaluator(morphology, trial_config, config.controller, config.robust, bodies)


def failed_result(a: TrialAssignment, reason: str, wall_time_s: float) -> TrialResult:
    return TrialResult.failed(reason[:150], a.seed, wall_time_s=wall_time_s)


def missing_config(run_id: str, config_hash: str, received: list[RunConfig], refused: int, timeout_s: float) -> str:
    """Why granted trials cannot run here, in one line: no config of the grant's hash came back."""
    hashes = ", ".join(c.config_hash() for c in received) or "none"
    return (f"cannot run the trials granted in run {run_id}: received {len(received)} run config(s) (hashes: {hashes}) "
            f"and {refused} refused or malformed replies within {timeout_s:g} s, expected the config of hash "
            f"{config_hash}; the trials go back to the coordinator with the next request")
