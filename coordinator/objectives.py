"""The score a search maximises, computed from a trial's stored parts (every part is stored anyway)."""

from __future__ import annotations

import math
from collections.abc import Callable

from spinefarm.protocol.errors import ConfigError
from spinefarm.protocol.messages import TrialResult


def _distance(r: TrialResult) -> float:
    return r.distance_m


def _speed(r: TrialResult) -> float:
    return r.speed_cm_s


def _cot_penalised(r: TrialResult) -> float:
    # Distance divided by (1 + COT): equal distances rank by efficiency; COT inf (no motion) scores 0.
    if not math.isfinite(r.cot):
        return 0.0
    return r.distance_m / (1.0 + max(r.cot, 0.0))


def _pareto_scalar(r: TrialResult) -> float:
    # `pareto` keeps the front of speed (max) and COT (min); samplers without a multi-objective mode
    # and the best-so-far use speed / (1 + COT): at equal COT faster wins, at equal speed cheaper wins.
    if not math.isfinite(r.cot):
        return 0.0
    return r.speed_cm_s / (1.0 + max(r.cot, 0.0))


OBJECTIVES: dict[str, Callable[[TrialResult], float]] = {
    "distance": _distance,
    "speed": _speed,
    "cot_distance": _cot_penalised,
    "pareto": _pareto_scalar,
}


def objective_fn(name: str) -> Callable[[TrialResult], float]:
    try:
        return OBJECTIVES[name]
    except KeyError:
        raise ConfigError("unknown objective", received=name, expected=sorted(OBJECTIVES)) from None
