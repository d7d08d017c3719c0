"""The score a search maximises, computed from a trial's stored parts (every part is stored anyway)."""

from __future__ import annotations

import math
from collections.abc import Callable

from spinefarm.protocol.errors import ConfigError
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.robust import EpisodeResult


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
# `cot:S`: the least COT among gaits of at least S cm/s (a speed to keep, e.g. a published gait's)
COT_AT_SPEED = "cot:"
OBJECTIVE_NAMES = (*OBJECTIVES, f"{COT_AT_SPEED}MIN_SPEED_CM_S")


def cot_at_speed(min_speed_cm_s: float) -> Callable[[TrialResult], float]:
    """Any gait of at least min_speed_cm_s outranks every slower one: the fast ones score 1 + 1/(1 + COT)
    in (1, 2], the slower ones speed / min_speed_cm_s in [0, 1), so a search first reaches the speed and
    then lowers the COT while it keeps it."""

    def score(r: TrialResult) -> float:
        if not math.isfinite(r.speed_cm_s) or r.speed_cm_s <= 0.0:
            return 0.0
        if r.speed_cm_s < min_speed_cm_s:
            return r.speed_cm_s / min_speed_cm_s
        return 1.0 + 1.0 / (1.0 + max(r.cot, 0.0)) if math.isfinite(r.cot) else 1.0

    return score


def objective_fn(name: str) -> Callable[[TrialResult], float]:
    if isinstance(name, str) and name.startswith(COT_AT_SPEED):
        text = name[len(COT_AT_SPEED):]
        try:
            min_speed_cm_s = float(text)
        except ValueError:
            min_speed_cm_s = math.nan
        if not (math.isfinite(min_speed_cm_s) and min_speed_cm_s > 0.0):
            raise ConfigError("the cot objective's speed to keep is not a positive number of cm/s",
                              received=name, expected=f"{COT_AT_SPEED}S with S > 0 cm/s, e.g. cot:6.13")
        return cot_at_speed(min_speed_cm_s)
    try:
        return OBJECTIVES[name]
    except (KeyError, TypeError):
        raise ConfigError("unknown objective", received=name, expected=list(OBJECTIVE_NAMES)) from None


def robust_objective(fn: Callable[[TrialResult], float], name: str) -> Callable[[TrialResult], float]:
    """The objective of a robust run: `fn` of every episode, reduced by the statistic `name` (mean, q25,
    min; protocol.robust). A result without episodes (a failed lease, a plain run) scores as `fn` alone."""
    from spinefarm.protocol.robust import statistic

    statistic([0.0], name)  # an unknown statistic fails here, not at the first result

    def robust(r: TrialResult) -> float:
        if not r.episodes:
            return fn(r)
        return statistic([fn(episode_result(r, e)) for e in r.episodes], name)

    return robust


def episode_result(r: TrialResult, e: EpisodeResult) -> TrialResult:
    """Episode `e` of result `r` as a TrialResult of its own (the robot's mass and extras of `r`)."""
    from spinefarm.protocol.measured import measured_numbers
    from spinefarm.protocol.states import TrialStatus

    return TrialResult(status=TrialStatus(e.status), reason=e.reason, **measured_numbers(e), mass_kg=r.mass_kg,
                       seed=e.seed, trial_id=r.trial_id, worker_id=r.worker_id, extras=r.extras)
