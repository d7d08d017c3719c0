"""`spinefarm fit` without the command line: recordings in, fitted constants, their spread and the before/after
figures out. Hold-out recordings are only reported: the loss sees the fitted recordings alone."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import Any

from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.profile import apply_profile, current_value
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.fit.loss import Prepared, candidate_loss, fit_loss, report, window_error_cm
from spinefarm.worker.fit.search import Bound, minimise

# makes a generation's losses for one fit (its robot, trial config and recordings): callable on a list of
# candidates, with close()
LossesMaker = Callable[[Morphology, TrialConfig, Sequence[Prepared]], Any]
AT_BOUND = 0.01  # a fitted value this near its bounds (in the unit cube) may want to lie beyond them


def with_values(cfg: TrialConfig, values: Mapping[str, float]) -> TrialConfig:
    return dataclasses.replace(cfg, profile={**cfg.profile, **values})


class Losses:
    """A generation's candidate losses (search.minimise's `losses`): in this process one after another, or with
    jobs > 1 in that many processes, each holding the robot and the recordings once. The project's workers over
    Zenoh are the other way (worker.fit.remote.RemoteLosses, made by a LossesMaker)."""

    def __init__(self, morph: Morphology, cfg: TrialConfig, fitted: Sequence[Prepared], jobs: int = 1) -> None:
        self.task = (morph, cfg, list(fitted))
        self.pool = None if jobs <= 1 else ProcessPoolExecutor(jobs, initializer=_hold, initargs=self.task)

    def __call__(self, candidates: list[dict[str, float]]) -> list[float]:
        if self.pool is None:
            return [_loss(self.task, v) for v in candidates]
        return list(self.pool.map(_held_loss, candidates))

    def close(self) -> None:
        if self.pool is not None:
            self.pool.shutdown()


_HELD: tuple = ()  # a pool process's (morph, cfg, recordings), sent once


def _hold(*task: Any) -> None:
    global _HELD
    _HELD = task


def _held_loss(values: dict[str, float]) -> float:
    return _loss(_HELD, values)


def _loss(task: tuple, values: dict[str, float]) -> float:
    morph, cfg, fitted = task
    return candidate_loss(morph, with_values(cfg, values), fitted)


def fit_constants(morph: Morphology, cfg: TrialConfig, fitted: Sequence[Prepared], held_out: Sequence[Prepared],
                  bounds: Sequence[Bound], restarts: int = 3, evaluations: int = 120, seed: int = 0,
                  progress: Callable[[int, int], None] | None = None, jobs: int | LossesMaker = 1) -> dict[str, Any]:
    """Fit `bounds`' constants to the `fitted` recordings, starting from the model's values under cfg's profile
    (the candidates' losses in `jobs` processes, or by what the LossesMaker `jobs` makes: the workers over
    Zenoh); the figures per recording (fitted and held out) before and after."""
    start = {b.name: min(max(current_value(apply_profile(morph, cfg.profile), b.name, cfg.engine,
                                           {**cfg.engine_options, **_engine_part(cfg)}), b.low), b.high)
             for b in bounds}
    losses = jobs(morph, cfg, fitted) if callable(jobs) else Losses(morph, cfg, fitted, jobs)
    try:
        found = minimise(losses, bounds, start, restarts, evaluations, seed, progress)
    finally:
        losses.close()
    after = with_values(cfg, found.values)
    spread = found.spread()
    return {
        "constants": {b.name: {"start": start[b.name], "fitted": found.values[b.name], "low": b.low, "high": b.high,
                               "at_bound": not AT_BOUND <= b.unit(found.values[b.name]) <= 1 - AT_BOUND,
                               **spread[b.name]} for b in bounds},
        "window_error_cm": {"before": window_error_cm(morph, cfg, list(fitted)),
                            "after": window_error_cm(morph, after, list(fitted))},
        "loss": {"before": fit_loss(morph, cfg, list(fitted)), "after": found.loss},
        "recordings": {p.name: {"held_out": p in held_out, "before": report(morph, cfg, p),
                                "after": report(morph, after, p)} for p in (*fitted, *held_out)},
        "restarts": [{"loss": loss, "values": v} for loss, v in found.restarts],
        "evaluations": found.evaluations, "profile": after.profile,
    }


def _engine_part(cfg: TrialConfig) -> dict[str, float]:
    from spinefarm.robot.profile import engine_options

    return engine_options(cfg.profile, cfg.engine)
