"""What a parameter set ranks by: its highest-fidelity evaluation.

A set the judge re-simulated (holds, moved, judged) ranks by the judged distance: for objectives that are a
distance, a speed or either over (1 + COT), the screen's objective times judged / screen distance (the same
simulated time); for the COT ones (cot_distance, pareto) also times (1 + screen COT) / (1 + judge's COT), the
judge's COT read from its evaluation row (`judge_cot`; a judge that did not move scores 0; a file from before
that column, or a judge's run without a row, keeps the screen's COT). `cot:S` keeps the screen's value. Any
other set ranks by its screen objective times the screen's bias as the judge measured it (screen_bias: one over
the smallest screen-to-judge ratio of the last three judged bests that moved 10 cm or more; 1 before there are
three): the best the judge could find it, by the closest recent reading. Without it a screen that reads a few
per cent high ranks every near-copy of a judged best above it, and the judge walks down a converged search's
plateau one set at a time (a paper-size search judged 54 such sets, 30 s of Bullet each, with 2,140 more
waiting at its end). Scaling every screened set alike keeps their order among themselves, so promotions do not
change.
A diverged (or, in older files, not-reproduced) judgement and a disputed or failed audit keep a set
from being best (base.best_ids).

With auditing on, the best a run reports is the best set another identity's audit agreed with (reported_best):
a better one still waiting for that audit is shown apart as "pending audit", never as the best.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from spinefarm.protocol.states import JUDGED_VERDICTS, REFUTED_VERDICTS, AuditState, EvaluationKind, TrialStatus

SCALED_OBJECTIVES = ("distance", "speed", "cot_distance", "pareto")  # proportional to the distance
COT_OBJECTIVES = ("cot_distance", "pareto")  # a distance or speed over (1 + COT)
_TINY_M = 1e-12
# a best that barely moves says nothing of the screen: a few millimetres of step error are a factor of 4 on the
# first bests of a search, which move a few centimetres (the judge's drift rule reads the same population)
MOVED_M = 0.1
BIAS_MIN_JUDGED = 3   # the drift rule's window: one or two ratios are a single gait's luck


def judge_ratios(cols: Mapping[str, np.ndarray]) -> np.ndarray:
    """The screen-to-judge ratios the judge measured on bests that moved MOVED_M or more, in trial-id order."""
    ratio = np.asarray(cols["judge_ratio"], dtype=float)
    moved = np.fmax(cols["distance_m"], cols["verify_distance_m"]) >= MOVED_M
    return ratio[np.isfinite(ratio) & moved]


def screen_bias(cols: Mapping[str, np.ndarray]) -> float:
    """Judged over screen distance as the judge found it where the search is now, at its most favourable: 1 / the
    smallest of the last BIAS_MIN_JUDGED judge_ratios (trial-id order, judged verdicts only, bests that moved);
    1 before there are that many. The smallest: a screened set is passed over
    only if it could not beat the judged best even as close to the judge as the closest recent reading (a
    median of a search's first ratios, 2.6 and 1.4 in the paper-size search against 1.05 near its best, kept
    its best sets from ever being judged). The last ones: an early reading says little of the screen now."""
    judged = np.isin(cols["verification"], JUDGED_VERDICTS)   # every schema has the column (NaN where unjudged)
    ratios = judge_ratios({k: np.asarray(cols[k])[judged] for k in ("judge_ratio", "distance_m", "verify_distance_m")})
    if ratios.size < BIAS_MIN_JUDGED:
        return 1.0
    closest = float(np.min(ratios[-BIAS_MIN_JUDGED:]))
    return 1.0 / closest if closest > 0 else 1.0


def judged_speed_cm_s(judged_distance_m: float, sim_time_s: float) -> float:
    """A judged set's speed: its judged distance over the simulated time (the judge runs as long as the screen);
    NaN without a simulated time."""
    return 100.0 * judged_distance_m / sim_time_s if sim_time_s else math.nan


def ranked_value(objective_name: str, objective: float, distance_m: float, verification: bytes,
                 verify_distance_m: float, cot: float = math.nan, judge_cot: float = math.nan,
                 bias: float = 1.0) -> float:
    """The value a complete set ranks by (see the module's doc); cot: the screen's, judge_cot: the judge's,
    bias: the run's screen_bias."""
    cols = {"objective": np.array([objective]), "distance_m": np.array([distance_m]),
            "verification": np.array([verification]), "verify_distance_m": np.array([verify_distance_m]),
            "cot": np.array([cot]), "judge_cot": np.array([judge_cot])}
    return float(ranked_values(cols, objective_name, bias)[0])


def is_judged(cols: Mapping[str, np.ndarray], objective_name: str) -> np.ndarray:
    """Rows that rank by the judge's figure rather than the screen's."""
    judged = np.isin(cols["verification"], JUDGED_VERDICTS) & np.isfinite(cols["verify_distance_m"])
    if objective_name != "distance":
        judged &= np.abs(np.asarray(cols["distance_m"], dtype=float)) > _TINY_M
    return judged


def ranked_values(cols: Mapping[str, np.ndarray], objective_name: str, bias: float = 1.0) -> np.ndarray:
    """ranked_value of every row at once; bias: the run's screen_bias (computed over all its rows, not these)."""
    obj = np.asarray(cols["objective"], dtype=float)
    if objective_name not in SCALED_OBJECTIVES:
        return obj
    judged = is_judged(cols, objective_name)
    screened = np.where(obj > 0, obj * bias, obj)   # a set that went backwards is not made to look better
    if objective_name == "distance":
        return np.where(judged, cols["verify_distance_m"], screened)
    d = np.asarray(cols["distance_m"], dtype=float)
    ratio = np.divide(cols["verify_distance_m"], d, out=np.ones_like(obj), where=judged)
    if objective_name in COT_OBJECTIVES and "judge_cot" in cols:
        ratio = ratio * _cot_factor(np.asarray(cols["cot"], dtype=float), np.asarray(cols["judge_cot"], dtype=float))
    return np.where(judged, obj * ratio, screened)


def _cot_factor(screen_cot: np.ndarray, judge_cot: np.ndarray) -> np.ndarray:
    """(1 + screen COT) / (1 + judge's COT), negative COTs as 0 as the objectives take them: 0 where the judge did
    not move (COT inf), 1 where its COT is unknown (NaN) or the screen's is not finite (its objective is 0)."""
    known = np.isfinite(judge_cot) & np.isfinite(screen_cot)
    factor = np.divide(1.0 + np.maximum(screen_cot, 0.0), 1.0 + np.maximum(judge_cot, 0.0),
                       out=np.ones_like(screen_cot), where=known)
    return np.where(np.isposinf(judge_cot) & np.isfinite(screen_cot), 0.0, factor)


def judge_cots(evaluations: Mapping[str, np.ndarray], trial_ids: np.ndarray) -> np.ndarray:
    """The COT of each set's latest complete judge run (NaN: none, or stored before the column)."""
    out = np.full(len(trial_ids), math.nan)
    if "cot" not in evaluations or not len(evaluations["cot"]):
        return out
    judge = (evaluations["kind"] == EvaluationKind.JUDGE.stored) & (evaluations["status"] == b"complete")
    for row in np.flatnonzero(judge):  # few rows: the judged bests; a later run overwrites an earlier
        hit = np.flatnonzero(trial_ids == evaluations["trial_id"][row])
        out[hit] = evaluations["cot"][row]
    return out


# another identity reproduced the result (or a referee upheld it against its auditor): it may be reported best
AGREEING_AUDITS = (AuditState.AGREES.stored, AuditState.OVERRULED.stored)


def agreeing(audit: np.ndarray) -> np.ndarray:
    """Which rows another identity's audit agreed with (or whose referee upheld them against the auditor)."""
    return (audit == AGREEING_AUDITS[0]) | (audit == AGREEING_AUDITS[1])   # two compares: np.isin sorts


# a row whose figure is being checked again (its worker quarantined, or its audit disputed): not learnt yet
_RECHECKED = (AuditState.QUARANTINED.stored, AuditState.DISPUTED.stored)
_AMENDED = (*_RECHECKED, AuditState.DISAGREES.stored)


def learned_columns(cols: Mapping[str, np.ndarray], objective_name: str) -> dict[str, np.ndarray]:
    """The objective (and speed) a sampler learns from each row, where they differ from the stored ones (empty
    when none does), so a model-based sampler never keeps learning a forged figure: a row being checked again
    reads NaN (unknown: a sampler takes it as it takes a failed row) until its re-run comes back; a row another
    identity did not reproduce (disagrees) reads that identity's distance (objectives proportional to the
    distance scale with it; any other objective reads NaN, its honest value unmeasured)."""
    audit = cols["audit"]
    rechecked, wrong = np.isin(audit, _RECHECKED), audit == AuditState.DISAGREES.stored
    if not (rechecked.any() or wrong.any()):
        return {}
    d = np.asarray(cols["distance_m"], dtype=float)
    ratio = np.divide(cols["audit_distance_m"], d, out=np.full(d.shape, math.nan), where=np.abs(d) > _TINY_M)
    out = {}
    for name in ("objective", "speed_cm_s"):
        value = np.array(cols[name], dtype=float)
        if name == "objective" and objective_name == "distance":
            value[wrong] = cols["audit_distance_m"][wrong]
        elif name == "speed_cm_s" or objective_name in SCALED_OBJECTIVES:
            value[wrong] *= ratio[wrong]
        else:
            value[wrong] = math.nan
        value[rechecked] = math.nan
        out[name] = value
    return out


def learned_revision(audit: np.ndarray) -> bytes:
    """Which rows learned_columns amends, and how: when it changes, what a sampler learnt from them is stale."""
    ids = np.flatnonzero(np.isin(audit, _AMENDED))
    return ids.tobytes() + audit[ids].tobytes()


def counted_distance_m(verification: str | bytes, distance_m: float, verify_distance_m: float) -> float:
    """The distance that counts for a set: the judge's when it judged the set, else the screen's."""
    v = verification.encode() if isinstance(verification, str) else verification
    return verify_distance_m if v in JUDGED_VERDICTS and math.isfinite(verify_distance_m) else distance_m


def evaluation_counts(cols: Mapping[str, np.ndarray],
                      evaluations: Mapping[str, np.ndarray] | None = None) -> dict[str, int]:
    """parameter_sets_done: sets whose first rung finished; evaluations_done: every finished simulation of any
    set (screen rungs, judge runs, audits and referees; a judge's perturbed twin runs inside its task), and the
    second engine's opinions, which only the evaluations table (`evaluations`) records."""
    finished = np.isin(cols["status"], (TrialStatus.COMPLETE.stored, TrialStatus.FAILED.stored))
    judged = np.isin(cols["verification"], (*JUDGED_VERDICTS, *REFUTED_VERDICTS))
    audited = np.isin(cols["audit"], _AUDITED)
    refereed = np.isin(cols["audit"], _REFEREED)
    return {"parameter_sets_done": int(np.count_nonzero(finished & (cols["rung"] == 0))),
            "evaluations_done": int(np.count_nonzero(finished) + np.count_nonzero(judged)
                                    + np.count_nonzero(audited) + np.count_nonzero(refereed)
                                    + _opinions(evaluations))}


def _opinions(evaluations: Mapping[str, np.ndarray] | None) -> int:
    if evaluations is None or "kind" not in evaluations:
        return 0
    return int(np.count_nonzero(evaluations["kind"] == EvaluationKind.OPINION.stored))


_AUDITED = tuple(a.stored for a in (AuditState.AGREES, AuditState.DISPUTED, AuditState.DISAGREES,
                                    AuditState.OVERRULED))
# a referee ran (a quarantined worker's disagreeing re-run has none; stored alike, it counts one)
_REFEREED = (AuditState.DISAGREES.stored, AuditState.OVERRULED.stored)
