"""`spinefarm fit` without the command line: recordings in, fitted constants, their spread and the before/after
figures out. Hold-out recordings are only reported: the loss sees the fitted recordings alone."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.profile import apply_profile, current_value
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.fit.loss import Prepared, candidate_loss, fit_loss, report, window_error_cm
from spinefarm.worker.fit.search import Bound, minimise

AT_BOUND = 0.01  # a fitted value this near its bounds (in the unit cube) may want to lie beyond them


def with_values(cfg: TrialConfig, values: Mapping[str, float]) -> TrialConfig:
    return dataclasses.replace(cfg, profile={**cfg.profile, **values})


def fit_constants(morph: Morphology, cfg: TrialConfig, fitted: Sequence[Prepared], held_out: Sequence[Prepared],
                  bounds: Sequence[Bound], restarts: int = 3, evaluations: int = 120, seed: int = 0,
                  progress: Callable[[int, int], None] | None = None) -> dict[str, Any]:
    """Fit `bounds`' constants to the `fitted` recordings, starting from the model's values under cfg's profile;
    the figures per recording (fitted and held out) before and after."""
    start = {b.name: min(max(current_value(apply_profile(morph, cfg.profile), b.name, cfg.engine,
                                           {**cfg.engine_options, **_engine_part(cfg)}), b.low), b.high)
             for b in bounds}
    found = minimise(lambda v: candidate_loss(morph, with_values(cfg, v), list(fitted)), bounds, start,
                     restarts, evaluations, seed, progress)
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
