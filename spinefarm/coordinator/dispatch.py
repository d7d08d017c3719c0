"""The coordinator's tasks beside the search's own trials, as CoordinatorCore's mixin: which worker may
run which task (its engines, an audit on another worker, no quarantined worker), each lease's fidelity,
the judge of the best, results of judges, audits and referees, and quarantines. Every method is called
with the core's lock held."""

from __future__ import annotations

import logging
from typing import Any

from spinefarm.coordinator.tasks import REFEREE, split_key, task_key
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.settings import TaskFidelity
from spinefarm.protocol.states import UNAUDITED
from spinefarm.protocol.submissions import Verdict
from spinefarm.protocol.work import TrialAssignment

log = logging.getLogger("spinefarm.coordinator")


class TaskDispatch:
    """Needs the core's study, scheduler, tasks, peers, clock and drift."""

    # --- tasks beside the search: the judge and the audit --------------------------------------------
    def _ask(self) -> int | None:
        """A new row for the search, unless it is done (tasks may still be running)."""
        return self.study.ask()

    def _eligible(self, key: int, worker_id: str) -> bool:
        """May `worker_id` run `key`: it runs that engine, and an audit goes to another identity."""
        if self.peers.is_quarantined(worker_id):
            return False
        checked = self.tasks.excluded(key)
        if checked and (worker_id in checked or not self.peers.may_check(worker_id, checked)):
            return False
        return self.peers.runs(worker_id, self._fidelity(key).engine or self.tasks.run_engine)

    def _fidelity(self, key: int) -> TaskFidelity:
        kind, tid = split_key(key)
        if kind != "trial":
            return self.tasks.task_fidelity(key)
        return self.tasks.trial_fidelity(int(self.study.storage.columns()["rung"][tid]), self.drift is not None)

    def _assignment(self, ls: Any) -> TrialAssignment:
        _, tid = split_key(ls.trial_id)
        cols = self.study.storage.columns()
        return TrialAssignment(tid, ls.lease_id, tuple(cols["params_unit"][tid].tolist()), int(cols["seed"][tid]),
                               ls.deadline_s - self.clock(), _duration(cols["duration_s"][tid]),
                               self._fidelity(ls.trial_id))

    def _judge_best(self) -> None:
        """Issue the judge of the current best unless it is judged or being judged; drop queued judges of
        bests since overtaken (lock held)."""
        audit = self.tasks.best_audit_due()
        if audit is not None:
            self.scheduler.push_front(audit)
        for key, stale in (self.tasks.judge_due(self.study.trial_scheduler.top, self.study.done),
                           self.tasks.opinion_due(self.study.done)):
            if key is None and not stale:
                continue
            for old in stale:
                if self.scheduler.queued(old) or split_key(old)[0] == "opinion":
                    self.scheduler.withdraw(old)
                    self.tasks.drop(old)
            if key is not None:
                self.scheduler.push_front(key)

    def _drop_unservable_tasks(self) -> None:
        """Once the search is over: judges of overtaken bests are stopped (a worker still running one
        finds its result stale), and tasks no live worker may run are dropped, so the run can end
        (lock held)."""
        # just (re)started: the workers that may run a task are still reconnecting
        reconnecting = self.clock() < self.scheduler.grace_until_s
        best = self.study.storage.best_ids(1)
        alive = [w.worker_id for w in self.scheduler.workers.values() if w.alive]
        for key in list(self.tasks.pending):
            kind, tid = split_key(key)
            overtaken = kind in ("judge", "opinion") and (not best or best[0] != tid)
            # a live worker whose identity is still being asked may be the one that can run it
            if overtaken or not (reconnecting or any(self._eligible(key, w) or self.peers.identity(w) is None
                                                     for w in alive)):
                # an audit no other identity can run stays pending, said as such, never silently dropped
                unaudited = kind == "audit" and not overtaken
                if unaudited:
                    self.unaudited[tid] = UNAUDITED
                    log.warning("no other worker identity can audit trial %d: it stays %s", tid, UNAUDITED)
                elif not overtaken:
                    log.warning("no worker can run the %s task of trial %d: dropped", kind, tid)
                    if kind == "opinion":
                        self.tasks.unservable.add(key)
                self.scheduler.withdraw(key)
                self.tasks.drop(key, keep_pending=unaudited)
        self._judge_best()

    def _refuse_quarantined(self, key: int, worker_id: str) -> Verdict | None:
        """A quarantined worker's results are not taken: the task goes to another worker (lock held)."""
        if not self.peers.is_quarantined(worker_id):
            return None
        self.scheduler.withdraw(key)
        self.scheduler.push_front(key)
        return Verdict.STALE

    def _quarantine(self, worker_ids: list[str], why: str) -> None:
        """Take back everything workers just quarantined hold; mark every row they stored and have it re-run by
        another identity (lock held)."""
        if not worker_ids:
            return
        for w in worker_ids:
            self.scheduler.take_back(w)
        reruns, settled = self.tasks.mark_quarantined(worker_ids)
        for key in settled:
            self.scheduler.withdraw(key)
        for key in reruns:
            self.scheduler.push_front(key)
        log.warning("worker(s) %s quarantined (%s); %d of their results marked and re-run elsewhere",
                    ", ".join(worker_ids), why, len(reruns))

    def identified(self, worker_id: str, sessions: set[str]) -> None:
        """The Zenoh sessions that answered for `worker_id` (the service's probe)."""
        with self.lock:
            self._quarantine(self.peers.identified(worker_id, sessions), "its session's other worker was")

    def _settle_task(self, key: int, worker_id: str, result: TrialResult) -> Verdict:
        """A judge's or an audit's result (lock held)."""
        kind, tid = split_key(key)
        if result.seed != int(self.study.storage.columns()["seed"][tid]):
            return Verdict.INVALID
        refused = self._refuse_quarantined(key, worker_id)
        if refused is not None:
            return refused
        self.scheduler.release(key)
        self.tasks.pending.discard(key)
        result = self._finite_or_failed(result)
        if kind == "judge":
            self.tasks.settle_judge(tid, result)
            drift = self.tasks.drift()
            if drift and not self.drift:
                log.warning("the judge no longer trusts the screen (%s): raising the screen's fidelity", drift)
            self.drift = drift
        elif kind == "opinion":
            self.tasks.settle_opinion(tid, result)
        else:
            row = self.study.storage.trial(tid)
            exact = self.peers.same_environment(row.worker_id, worker_id)
            judged = self.tasks.settle_audit(tid, result, worker_id, exact) if kind == "audit" \
                else self.tasks.settle_referee(tid, result, exact)
            self.audit_comparisons["exact" if exact else "tolerance"] += 1
            for wid, agrees in judged:
                self._quarantine(self.peers.audited(wid, agrees), "its audited results disagree with other "
                                                                  "workers'")
            if kind == "audit" and task_key(REFEREE, tid) in self.tasks.pending:
                self.scheduler.push_front(task_key(REFEREE, tid))
        self._judge_best()
        return Verdict.STORED



def _duration(value: float) -> float | None:
    """A row's requested duration for the wire: None (the run's own) when it has none."""
    return float(value) if value == value else None
