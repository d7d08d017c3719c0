"""The ladder's checks beside the screen's rows, run by workers like any trial: the judge, audits, referees
and the second engine's opinion. Checks (one per run, under the core's lock) says which is due, at which
fidelity, and stores what each found.

- The judge re-simulates every new full-length best at the judge's rung before it counts (a finer
  step in the same engine, or another engine); its verdicts are protocol.verdicts' ("holds" within
  the robot's chaos floor, "moved X % at the finer step", "judged", "diverged"). A judged set ranks by
  its judged distance (storage.ranking); a diverged one never counts as best and the next best is judged.
- The opinion runs a judged best once in the engine the judge does not use, at its converged step; it
  never ranks (the models' spread, docs/distributed.md).
- The audit re-simulates a fraction of the results (and every new best) on another worker at the same
  fidelity; a disagreement is refereed by a third worker; a disputed result never counts as best.
- The judge (its runs and the opinions) takes at most its share of the workers' time while the search
  runs (JudgePolicy.share), counted from the stored evaluation rows; once the search is over the best is
  judged whatever it cost.
- The judge watches the screen: once three judged ratios in a row (trial-id order; bests that move 10 cm or
  more in either run) have a median outside [1 - drift, 1 + drift], the ladder's fidelity is raised for every
  trial leased from then on (the judge's engine at 4x the judge's step when the judge is another engine, else
  half the step).

What is pending lives in storage (verification and audit columns: pending, then the verdict; an opinion is
due while the judged best has no opinion row), so a restarted coordinator issues every pending check again.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import math

import numpy as np

from spinefarm.coordinator.ladder.keys import AUDIT, JUDGE, KIND_CODES, OPINION, REFEREE, TRIAL, check_key, split_key
from spinefarm.protocol.errors import StorageError
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.settings import RunSettings, TaskFidelity
from spinefarm.protocol.states import JUDGED_VERDICTS, AuditState, EvaluationKind, Verification
from spinefarm.protocol.verdicts import judge_verdict, relative_change
from spinefarm.robot.chaos_floors import holds_tolerance
from spinefarm.storage.base import BaseStorage
from spinefarm.storage.evaluations import judge_wall_s, row_of
from spinefarm.storage.ranking import BIAS_MIN_JUDGED, judge_ratios

log = logging.getLogger("spinefarm.coordinator")
# a judge run stopped by its wall-clock limit is issued again this many times before it counts as diverged
_JUDGE_TIMEOUT_RETRIES = 2
_DRIFT_WINDOW = BIAS_MIN_JUDGED   # three ratios, as the screen's bias the ranking applies


class Checks:
    """Which check is due (judge, audit, referee, opinion), at which fidelity, and what each found (lock held)."""

    def __init__(self, storage: BaseStorage, settings: RunSettings, run_engine: str | None, seed: int,
                 judged: bool) -> None:
        self.storage = storage
        self.settings = settings
        self.run_engine = run_engine
        self.seed = seed
        self.judged = judged   # the run has a judge (test objectives only when one is named)
        self.pending: set[int] = set()   # check keys issued and not yet settled
        self.unservable: set[int] = set()   # opinions no live worker could run (tried again on a restart)
        # the time the judge's runs took, from the stored evaluation rows: a restart keeps the judge's share
        self.judge_wall_s = 0.0
        with contextlib.suppress(StorageError):  # a store whose run is not created yet has no rows
            self.judge_wall_s = judge_wall_s(storage.evaluations())

    @functools.cached_property
    def holds(self) -> tuple[float, str]:
        """(the tolerance a same-engine judgement "holds" within, where it comes from): the robot's chaos floor."""
        meta = self.storage.run_meta()
        return holds_tolerance(meta.morphology, meta.morphology_spec, self.settings.judge.tolerance)

    # --- fidelity -----------------------------------------------------------------------------------
    @property
    def judge_engine(self) -> str | None:
        return self.settings.judge.rung.engine

    def drift(self) -> str | None:
        """Why the screen is no longer trusted (three judged ratios in a row drifted), or None."""
        ratios = judge_ratios(self.storage.columns())
        d = self.settings.judge.drift
        for i in range(len(ratios) - _DRIFT_WINDOW + 1):
            m = float(np.median(ratios[i:i + _DRIFT_WINDOW]))
            if not 1 - d <= m <= 1 + d:
                return f"median screen-to-judge ratio {m:.3g} of {_DRIFT_WINDOW} judged bests outside " \
                       f"[{1 - d:.3g}, {1 + d:.3g}]"
        return None

    def trial_fidelity(self, rung: int, raised: bool) -> TaskFidelity:
        r = self.settings.ladder[rung]
        if not raised:
            return TaskFidelity.of(TRIAL, r)
        judge = self.settings.judge.rung
        if judge.engine is not None and judge.engine != (r.engine or self.run_engine):
            return TaskFidelity(TRIAL, judge.engine, None if judge.dt_s is None else 4 * judge.dt_s, r.settle_s)
        step = r.dt_s if r.dt_s is not None else (None if judge.dt_s is None else 4 * judge.dt_s)
        return TaskFidelity(TRIAL, r.engine, None if step is None else step / 2, r.settle_s)

    def check_fidelity(self, key: int) -> TaskFidelity:
        kind, tid = split_key(key)
        if kind == EvaluationKind.JUDGE:
            return TaskFidelity.of(EvaluationKind.JUDGE, self.settings.judge.rung, self.settings.judge.perturb)
        if kind == EvaluationKind.OPINION and self.settings.judge.opinion is not None:
            return TaskFidelity.of(EvaluationKind.OPINION, self.settings.judge.opinion)
        row = self.storage.trial(tid)  # an audit (and its referee) re-runs the row exactly as it ran
        dt = row.dt_s if math.isfinite(row.dt_s) else None
        settle = row.settle_s if math.isfinite(row.settle_s) else None
        return TaskFidelity(EvaluationKind.AUDIT, row.engine or None, dt, settle)

    def excluded(self, key: int) -> set[str]:
        """Workers that may not run check `key`: an audit goes to another worker than the result's, a
        referee to a third one."""
        kind, tid = split_key(key)
        if kind not in (EvaluationKind.AUDIT, EvaluationKind.REFEREE):
            return set()
        row = self.storage.trial(tid)
        return {row.worker_id, row.audit_worker_id} if kind == EvaluationKind.REFEREE else {row.worker_id}

    # --- issuing ------------------------------------------------------------------------------------
    def restart(self) -> list[int]:
        """Check keys to issue again after a restart: every pending verification, audit and referee (opinions are
        due from storage alone: issue_due finds them)."""
        cols = self.storage.columns()
        keys = [check_key(JUDGE, int(t)) for t in np.flatnonzero(cols["verification"] == Verification.PENDING.stored)]
        rerun = np.isin(cols["audit"], (AuditState.PENDING.stored, AuditState.QUARANTINED.stored))
        keys += [check_key(AUDIT, int(t)) for t in np.flatnonzero(rerun)]
        keys += [check_key(REFEREE, int(t)) for t in np.flatnonzero(cols["audit"] == AuditState.DISPUTED.stored)]
        self.pending.update(keys)
        return keys

    def judge_due(self, top_rung: int, search_over: bool = False) -> tuple[int | None, list[int]]:
        """(the best's judge key if it is due, queued judge keys of overtaken bests to drop). While the
        search runs, a judge is due only within the judge's share of the workers' time."""
        if not (self.judged and self.settings.judge.enabled):
            return None, []
        best = self.storage.best_ids(1)
        if not best:
            return None, []
        tid = best[0]
        cols = self.storage.columns()
        key = check_key(JUDGE, tid)
        if int(cols["rung"][tid]) < top_rung or cols["verification"][tid] != Verification.NOT_CHECKED.stored:
            return None, []  # a screened best is provisional; a judged or pending one is on its way
        if not search_over and self.over_share(cols["wall_time_s"]):
            return None, []
        self.storage.set_verification(tid, Verification.PENDING)
        self.pending.add(key)
        return key, [k for k in self.pending if k != key and split_key(k)[0] == EvaluationKind.JUDGE]

    def opinion_due(self, search_over: bool = False) -> tuple[int | None, list[int]]:
        """(the current best's opinion key if it is due, pending opinion keys of overtaken bests to drop).
        Due once the best is judged (holds, moved, judged) and has no opinion row: decided from storage alone,
        so a restart issues it again; while the search runs only within the judge's share of the time."""
        opinion = self.settings.judge.opinion
        best = self.storage.best_ids(1)
        if opinion is None or not (self.judged and self.settings.judge.enabled and best):
            return None, []
        tid, key = best[0], check_key(OPINION, best[0])
        stale = [k for k in self.pending if k != key and split_key(k)[0] == EvaluationKind.OPINION]
        cols = self.storage.columns()
        if key in self.pending or key in self.unservable or cols["verification"][tid] not in JUDGED_VERDICTS:
            return None, stale
        ev = self.storage.evaluations()
        if np.any((ev["trial_id"] == tid) & (ev["kind"] == EvaluationKind.OPINION.stored)):
            return None, stale
        if not search_over and self.over_share(cols["wall_time_s"]):
            return None, stale
        self.pending.add(key)
        return key, stale

    def over_share(self, trial_wall_s: np.ndarray) -> bool:
        """Has the judge taken more than its share of the time spent in its runs and the trials'?"""
        share = self.settings.judge.share
        trials_s = float(np.sum(trial_wall_s, where=np.isfinite(trial_wall_s)))
        return self.judge_wall_s * (1.0 - share) > share * trials_s

    def drop(self, key: int, keep_pending: bool = False) -> None:
        """A check no longer wanted (an overtaken best's judge, an audit nobody can run). keep_pending: the row's
        audit stays pending in the file (re-issued on resume, when another identity may be there)."""
        self.pending.discard(key)
        kind, tid = split_key(key)
        if keep_pending or kind == EvaluationKind.OPINION:   # due from storage alone: nothing stored to undo
            return
        if kind == EvaluationKind.JUDGE:
            self.storage.set_verification(tid, Verification.NOT_CHECKED)
        elif kind == EvaluationKind.AUDIT and self.storage.columns()["audit"][tid] != AuditState.QUARANTINED.stored:
            self.storage.set_audit(tid, AuditState.NOT_AUDITED)   # a quarantined worker's row stays untrusted
        # a referee nobody can run leaves the result disputed (it does not count as best)

    def audit_due(self, tid: int) -> int | None:
        """The audit key of a just stored result, if it is to be audited: a fraction of them and
        every new best."""
        a = self.settings.audit
        if not a.enabled:
            return None
        best = self.storage.best_ids(1)
        drawn = np.random.default_rng([self.seed, tid, 0xA0D17]).random() < a.fraction
        if not (drawn or (best and best[0] == tid)):
            return None
        key = check_key(AUDIT, tid)
        self.storage.set_audit(tid, AuditState.PENDING)
        self.pending.add(key)
        return key

    def best_audit_due(self) -> int | None:
        """The audit of the current best if it has none: a result that becomes best later (the one before
        it fell) is audited too."""
        best = self.storage.best_ids(1)
        if not (self.settings.audit.enabled and best):
            return None
        if self.storage.columns()["audit"][best[0]] != AuditState.NOT_AUDITED.stored:
            return None
        key = check_key(AUDIT, best[0])
        self.storage.set_audit(best[0], AuditState.PENDING)
        self.pending.add(key)
        return key

    # --- results --------------------------------------------------------------------------------------
    def _record(self, tid: int, kind: EvaluationKind, r: TrialResult, worker_id: str = "") -> None:
        """Every judge, audit, referee and opinion run is a row of the evaluations table, linked to the row it
        checked."""
        f = self.check_fidelity(check_key(KIND_CODES[kind], tid))
        dt = r.extras.get("dt_s", f.dt_s)
        self.storage.add_evaluation(row_of(tid, kind, r, str(r.extras.get("engine", f.engine or "")),
                                           None if dt is None else float(dt), worker_id))

    def settle_judge(self, tid: int, r: TrialResult) -> None:
        if math.isfinite(r.wall_time_s):
            self.judge_wall_s += r.wall_time_s
        self._record(tid, EvaluationKind.JUDGE, r)
        if _timed_out(r) and self._judge_timeouts(tid) <= _JUDGE_TIMEOUT_RETRIES:
            # a wall-clock limit hit on a busy machine says nothing of the physics: the judge is due again
            self.storage.set_verification(tid, Verification.NOT_CHECKED)
            log.warning("the judge's run of trial %d timed out (%s): it is issued again", tid, r.reason)
            return
        row = self.storage.trial(tid)
        engine = str(r.extras.get("engine", "")) or (self.judge_engine or "")
        cross = self.judge_engine is not None and self.judge_engine != (row.engine or self.run_engine)
        verdict, reason = judge_verdict(row.distance_m, cross, engine, r, self.holds[0])
        ratio = row.distance_m / r.distance_m if r.ok and r.distance_m != 0 else math.nan
        self.storage.set_verification(tid, verdict, r.distance_m, reason, ratio)
        if verdict == Verification.DIVERGED:
            log.warning("best trial %d diverged in the judge's run (never best): %s", tid, reason)
        elif verdict == Verification.MOVED:
            log.info("best trial %d %s (%s); it ranks by its judged distance", tid, reason, self.holds[1])

    def _judge_timeouts(self, tid: int) -> int:
        ev = self.storage.evaluations()
        return int(np.count_nonzero((ev["trial_id"] == tid) & (ev["kind"] == EvaluationKind.JUDGE.stored)
                                    & np.char.startswith(ev["reason"], b"timeout:")))

    def settle_opinion(self, tid: int, r: TrialResult) -> None:
        """The other engine's run of a judged best: a row of its own, counted in the judge's share; it never ranks."""
        if math.isfinite(r.wall_time_s):
            self.judge_wall_s += r.wall_time_s
        self._record(tid, EvaluationKind.OPINION, r)
        row = self.storage.trial(tid)
        log.info("best trial %d in the other engine (%s): %.4g m against its judged %.4g m", tid,
                 r.extras.get("engine", ""), r.distance_m, row.verify_distance_m)

    def mark_quarantined(self, worker_ids: list[str]) -> tuple[list[int], list[int]]:
        """Every complete row of quarantined workers is marked and re-run by another identity (an audit); a row
        another identity's audit disputes is settled against them (that audit was its re-run). (audit keys
        to issue, referee keys no longer wanted); rows already being audited keep their audit."""
        cols = self.storage.columns()
        mine = np.isin(cols["worker_id"], [w.encode("utf-8", "replace")[:64] for w in worker_ids]) & (
            cols["status"] == b"complete")
        reruns, settled = [], []
        for tid in np.flatnonzero(mine & (cols["audit"] == AuditState.DISPUTED.stored)).tolist():
            row = self.storage.trial(tid)
            self.storage.set_audit(tid, AuditState.DISAGREES, row.audit_distance_m, row.audit_worker_id)
            if check_key(REFEREE, tid) in self.pending:
                self.pending.discard(check_key(REFEREE, tid))
                settled.append(check_key(REFEREE, tid))
        for tid in np.flatnonzero(mine & (cols["audit"] != AuditState.DISAGREES.stored)).tolist():
            self.storage.set_audit(tid, AuditState.QUARANTINED)
            key = check_key(AUDIT, tid)
            if key not in self.pending:
                self.pending.add(key)
                reruns.append(key)
        return reruns, settled

    def settle_audit(self, tid: int, r: TrialResult, worker_id: str, exact: bool) -> list[tuple[str, bool]]:
        """Store an audit; (worker, agreed) for each worker it judged. exact: both ran the same code in the same
        environment, so only the same bits agree (else the tolerance). A disagreement is refereed by a third
        worker before anybody is blamed; the re-run of a quarantined worker's row needs no referee."""
        self._record(tid, EvaluationKind.AUDIT, r, worker_id)
        row = self.storage.trial(tid)
        how = _comparison(exact, self.settings.audit.tolerance)
        tol = 0.0 if exact else self.settings.audit.tolerance
        if _same(r, row.status == "complete", row.distance_m, tol):
            self.storage.set_audit(tid, AuditState.AGREES, r.distance_m, worker_id)
            return [(row.worker_id, True), (worker_id, True)]
        if row.audit == AuditState.QUARANTINED:
            self.storage.set_audit(tid, AuditState.DISAGREES, r.distance_m, worker_id)
            log.warning("re-run of trial %d (its worker %s is quarantined) by worker %s: %.17g m against %.17g m "
                        "(%s)", tid, row.worker_id, worker_id, r.distance_m, row.distance_m, how)
            return []
        self.storage.set_audit(tid, AuditState.DISPUTED, r.distance_m, worker_id)
        self.pending.add(check_key(REFEREE, tid))
        log.warning("audit of trial %d disputed (%s): worker %s measured %.17g m, worker %s %.17g m; a third "
                    "worker referees", tid, how, row.worker_id, row.distance_m, worker_id, r.distance_m)
        return []

    def settle_referee(self, tid: int, r: TrialResult, exact: bool) -> list[tuple[str, bool]]:
        """The third worker's run decides a disputed audit: whoever it contradicts is wrong (the result's
        worker when it matches neither)."""
        self._record(tid, EvaluationKind.REFEREE, r)
        row = self.storage.trial(tid)
        tol = 0.0 if exact else self.settings.audit.tolerance
        if _same(r, row.status == "complete", row.distance_m, tol):
            self.storage.set_audit(tid, AuditState.OVERRULED, row.audit_distance_m, row.audit_worker_id)
            return [(row.audit_worker_id, False), (row.worker_id, True)]
        self.storage.set_audit(tid, AuditState.DISAGREES, row.audit_distance_m, row.audit_worker_id)
        log.warning("result of trial %d from worker %s not reproduced by two other workers", tid, row.worker_id)
        return [(row.worker_id, False)]


def _comparison(exact: bool, tolerance: float) -> str:
    """What an audit's verdict was held to, for its log line."""
    if exact:
        return "exact: same code and environment"
    return f"within {tolerance:.0%}: the workers' environments differ or are unknown"


def _same(r: TrialResult, ok: bool, distance_m: float, tolerance: float) -> bool:
    """`r` reproduces a stored outcome (both failed, or both complete within the relative tolerance)."""
    return r.ok == ok and (not ok or relative_change(r.distance_m, distance_m) <= tolerance)


def _timed_out(r: TrialResult) -> bool:
    return not r.ok and r.reason.startswith("timeout:")
