"""Ladder: the seam the coordinator's core asks, under its lock, what runs next and tells each result.

It decides every evaluation of a run from the stored rows: a screen row's rung (rungs.py, through the study's
trial scheduler) and its fidelity (raised once the judge stops trusting the screen), and the checks beside the
screen (checks.py: the judge of a new best, audits, referees, the second engine's opinion); which worker may run
which (its engines, another identity for an audit, no quarantined worker); a quarantine's rows marked and run
again. Called when a worker asks for work (`eligible`, `assignment`), when a result arrives (`after_trial`,
`settle_check`) and once the search is over (`drop_unservable`). A new Ladder rebuilds everything pending from
storage, so a restarted coordinator issues every pending evaluation again.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from spinefarm.coordinator.ladder.checks import Checks
from spinefarm.coordinator.ladder.keys import REFEREE, TRIAL, check_key, split_key
from spinefarm.coordinator.peers import PeerBook
from spinefarm.coordinator.scheduler import Scheduler
from spinefarm.coordinator.study import Study
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.settings import TaskFidelity
from spinefarm.protocol.states import UNAUDITED, EvaluationKind
from spinefarm.protocol.submissions import Verdict
from spinefarm.protocol.work import TrialAssignment

log = logging.getLogger("spinefarm.coordinator")


class Ladder:
    """One per run; the lease scheduler issues what it decides (see the module)."""

    def __init__(self, study: Study, leases: Scheduler, checks: Checks, peers: PeerBook,
                 clock: Callable[[], float]) -> None:
        self.study = study
        self.leases = leases
        self.checks = checks
        self.peers = peers
        self.clock = clock
        self.drift = checks.drift()  # why the screen's fidelity was raised (None: it was not)
        self.audit_comparisons = {"exact": 0, "tolerance": 0}   # what audits were held to (checks.settle_audit)
        self.unaudited: dict[int, str] = {}   # rows whose audit stays pending, and why
        self.continue_rungs = True   # a promotion may go on from its last rung's end (off: --no-continue)
        self.waiting_judges: set[int] = set()   # bests whose judge waits for a worker of its engine (said once)
        # the checks a restart cut short first, then the screen rows sampled but never finished
        leases.enqueue(checks.restart() + study.storage.waiting_ids())
        self.issue_due()

    @property
    def done(self) -> bool:
        """The search is done and so are its checks."""
        return self.study.done and not self.checks.pending

    def eligible(self, key: int, worker_id: str) -> bool:
        """May `worker_id` run `key`: it runs that engine, and an audit goes to another identity."""
        if self.peers.is_quarantined(worker_id):
            return False
        checked = self.checks.excluded(key)
        if checked and (worker_id in checked or not self.peers.may_check(worker_id, checked)):
            return False
        return self.peers.runs(worker_id, self.fidelity(key).engine or self.checks.run_engine)

    def fidelity(self, key: int) -> TaskFidelity:
        kind, tid = split_key(key)
        if kind != TRIAL:
            return self.checks.check_fidelity(key)
        return self.checks.trial_fidelity(int(self.study.storage.columns()["rung"][tid]), self.drift is not None)

    def assignment(self, lease: Any, now_s: float) -> TrialAssignment:
        _, tid = split_key(lease.trial_id)
        cols = self.study.storage.columns()
        # a check (judge, audit, referee, opinion) always simulates from the start: an independent re-run
        return TrialAssignment(tid, lease.lease_id, tuple(cols["params_unit"][tid].tolist()), int(cols["seed"][tid]),
                               lease.deadline_s - now_s, _duration(cols["duration_s"][tid]),
                               self.fidelity(lease.trial_id), split_key(lease.trial_id)[0] != TRIAL
                               or not self.continue_rungs)

    def issue_due(self) -> None:
        """Issue the checks now due: the best's audit if it has none, its judge unless it is judged or being
        judged, the judged best's opinion; queued judges and opinions of bests since overtaken are dropped."""
        audit = self.checks.best_audit_due()
        if audit is not None:
            self.leases.push_front(audit)
        for key, stale in (self.checks.judge_due(self.study.trial_scheduler.top, self.study.done),
                           self.checks.opinion_due(self.study.done)):
            for old in stale:
                if self.leases.queued(old) or split_key(old)[0] == EvaluationKind.OPINION:
                    self.leases.withdraw(old)
                    self.checks.drop(old)
            if key is not None:
                self.leases.push_front(key)

    def after_trial(self, result: TrialResult) -> None:
        """A screen row was stored: its audit if one is drawn, and whatever it made due."""
        if not result.ok:
            return
        audit = self.checks.audit_due(result.trial_id)
        if audit is not None:
            self.leases.push_front(audit)
        self.issue_due()

    def drop_unservable(self) -> None:
        """Once the search is over: judges and opinions of overtaken bests are stopped (a worker still running
        one finds its result stale), and checks no live worker may run are dropped, so the run can end."""
        # just (re)started: the workers that may run a check are still reconnecting
        reconnecting = self.clock() < self.leases.grace_until_s
        best = self.study.storage.best_ids(1)
        alive = [w.worker_id for w in self.leases.workers.values() if w.alive]
        for key in list(self.checks.pending):
            kind, tid = split_key(key)
            overtaken = kind in (EvaluationKind.JUDGE, EvaluationKind.OPINION) and (not best or best[0] != tid)
            # a live worker whose identity is still being asked may be the one that can run it
            if overtaken or not (reconnecting or any(self.eligible(key, w) or self.peers.identity(w) is None
                                                     for w in alive)):
                # an audit no other identity can run stays pending, said as such, never silently dropped
                unaudited = kind == EvaluationKind.AUDIT and not overtaken
                if unaudited:
                    self.unaudited[tid] = UNAUDITED
                    log.warning("no other worker identity can audit trial %d: it stays %s", tid, UNAUDITED)
                elif kind == EvaluationKind.JUDGE and not overtaken:
                    # issue_due queues the best's judge again: it waits, and is said so once
                    if tid not in self.waiting_judges:
                        self.waiting_judges.add(tid)
                        log.warning("no live worker can run the judge of trial %d: it waits for one", tid)
                elif not overtaken:
                    log.warning("no worker can run the %s check of trial %d: dropped", kind, tid)
                    if kind == EvaluationKind.OPINION:
                        self.checks.unservable.add(key)
                self.leases.withdraw(key)
                self.checks.drop(key, keep_pending=unaudited)
        self.issue_due()

    def refuse_quarantined(self, key: int, worker_id: str) -> Verdict | None:
        """A quarantined worker's results are not taken: the key goes to another worker."""
        if not self.peers.is_quarantined(worker_id):
            return None
        self.leases.withdraw(key)
        self.leases.push_front(key)
        return Verdict.STALE

    def quarantine(self, worker_ids: list[str], why: str) -> None:
        """Take back everything workers just quarantined hold; mark every row they stored and have it re-run by
        another identity."""
        if not worker_ids:
            return
        for w in worker_ids:
            self.leases.take_back(w)
        reruns, settled = self.checks.mark_quarantined(worker_ids)
        for key in settled:
            self.leases.withdraw(key)
        for key in reruns:
            self.leases.push_front(key)
        log.warning("worker(s) %s quarantined (%s); %d of their results marked and re-run elsewhere",
                    ", ".join(worker_ids), why, len(reruns))

    def settle_check(self, key: int, worker_id: str, result: TrialResult) -> Verdict:
        """A check's result (its score already finite or failed)."""
        kind, tid = split_key(key)
        if result.seed != int(self.study.storage.columns()["seed"][tid]):
            return Verdict.INVALID
        refused = self.refuse_quarantined(key, worker_id)
        if refused is not None:
            return refused
        self.leases.release(key)
        self.checks.pending.discard(key)
        if kind == EvaluationKind.JUDGE:
            self.checks.settle_judge(tid, result)
            drift = self.checks.drift()
            if drift and not self.drift:
                log.warning("the judge no longer trusts the screen (%s): raising the screen's fidelity", drift)
            self.drift = drift
        elif kind == EvaluationKind.OPINION:
            self.checks.settle_opinion(tid, result)
        else:
            self._settle_audit(kind, tid, worker_id, result)
        self.issue_due()
        return Verdict.STORED

    def _settle_audit(self, kind: str, tid: int, worker_id: str, result: TrialResult) -> None:
        row = self.study.storage.trial(tid)
        exact = self.peers.same_environment(row.worker_id, worker_id)
        judged = self.checks.settle_audit(tid, result, worker_id, exact) if kind == EvaluationKind.AUDIT \
            else self.checks.settle_referee(tid, result, exact)
        self.audit_comparisons["exact" if exact else "tolerance"] += 1
        for wid, agrees in judged:
            self.quarantine(self.peers.audited(wid, agrees), "its audited results disagree with other workers'")
        if kind == EvaluationKind.AUDIT and check_key(REFEREE, tid) in self.checks.pending:
            self.leases.push_front(check_key(REFEREE, tid))


def _duration(value: float) -> float | None:
    """A row's requested duration for the wire: None (the run's own) when it has none."""
    return float(value) if value == value else None
