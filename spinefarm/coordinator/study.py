"""Study: ask/tell over a storage and a sampler, with a trial budget and an objective."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from spinefarm.coordinator.ladder.rungs import Asker, BaseTrialScheduler, PlainTrialScheduler
from spinefarm.coordinator.samplers.base import BaseSampler, LearnedView, Proposal
from spinefarm.protocol.params import ParamSpace
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.settings import ENQUEUED, PROMOTED, RunSettings
from spinefarm.storage.base import BaseStorage
from spinefarm.storage.ranking import learned_revision


def trial_seed(run_seed: int, trial_id: int | np.ndarray) -> int | np.ndarray:
    """Seed of trial `trial_id` (an int or an integer array) in a run seeded with `run_seed`."""
    return (run_seed * 1_000_003 + trial_id) % (2**31 - 1)


class Study:
    """`ask` samples and records the next trial; `tell` stores a result once.

    Trial ids are dense row numbers; the seed of trial n is derived from the run seed and n. Which
    evaluation comes next on the fidelity ladder is the trial scheduler's (coordinator.ladder.rungs).
    """

    def __init__(self, storage: BaseStorage, sampler: BaseSampler, space: ParamSpace, budget: int,
                 objective: Callable[[TrialResult], float], seed: int,
                 trial_scheduler: BaseTrialScheduler | None = None,
                 enqueued: tuple[tuple[float, ...], ...] = ()) -> None:
        """budget counts new parameter sets (the enqueued ones among them); a scheduler's promotions to longer
        rungs come on top. enqueued: unit-cube parameter sets evaluated first, in order, before the sampler's."""
        self.trial_scheduler = trial_scheduler or PlainTrialScheduler(RunSettings())
        self.storage = storage
        self.sampler = sampler
        self.space = space
        self.budget = budget
        self.objective = objective
        self.seed = seed
        self.enqueued = enqueued
        self._n_finished = sum(v for k, v in storage.counts().items() if k != "waiting")
        self._learned = b""   # which rows' figures the sampler learnt amended (storage.ranking.learned_revision)
        self._audit_writes = -1   # storage.audit_writes when that was last looked at

    @property
    def n_asked(self) -> int:
        return self.storage.n_trials()

    @property
    def n_finished(self) -> int:
        return self._n_finished

    @property
    def n_sampled(self) -> int:
        """New parameter sets sampled so far (promotions re-run earlier ones)."""
        return self.trial_scheduler.n_sampled(self.storage)

    @property
    def planned(self) -> int:
        """Evaluations the run expects: the budget, plus the scheduler's promotions."""
        return self.trial_scheduler.planned(self.budget)

    @property
    def done(self) -> bool:
        return self.trial_scheduler.done(self.storage, self.budget, self._n_finished)

    def trial_seed(self, trial_id: int) -> int:
        return trial_seed(self.seed, trial_id)

    def ask(self, asker: Asker | None = None) -> int | None:
        """Sample and record the next trial (first a promotion to a longer rung, if one is due: with `asker`, one
        whose last rung that worker ran first, coordinator.ladder.rungs); None once the budget is allotted."""
        tid = self.storage.n_trials()
        ts = self.trial_scheduler
        sampling_done = self.n_sampled >= self.budget
        source = ts.promotion(self.storage, sampling_done, asker)
        if source is not None:
            row = self.storage.trial(source)
            unit = np.asarray(row.params_unit)
            self.storage.add_trial(tid, unit, self.space.from_unit(unit), PROMOTED, source,
                                   self.trial_seed(tid), row.rung + 1, ts.duration_s(row.rung + 1))
            return tid
        if sampling_done:
            return None
        self._relearn_if_amended()
        view = ts.sampler_view(self.storage)  # with rungs: proposal k is the k-th parameter set
        if self._learned:
            view = LearnedView(view, self.storage.run_meta().objective)
        k = view.n_trials()
        p = Proposal(np.asarray(self.enqueued[k]), ENQUEUED, -1) if k < len(self.enqueued) \
            else self.sampler.propose(k, view)
        self.storage.add_trial(tid, p.params_unit, self.space.from_unit(p.params_unit), p.phase,
                               ts.parent_id(view, p.parent), self.trial_seed(tid), 0, ts.duration_s(0))
        return tid

    def _relearn_if_amended(self) -> None:
        """A row's figure a sampler learnt was found forged (its worker quarantined) or re-run since: the sampler
        starts over and learns every row again as it now reads (model-based samplers learn a row once)."""
        if self.storage.audit_writes == self._audit_writes:
            return   # no audit changed: no row was amended (the audit column is not scanned per proposal)
        self._audit_writes = self.storage.audit_writes
        revision = learned_revision(self.storage.columns()["audit"])
        if revision != self._learned:
            self._learned = revision
            self.sampler = type(self.sampler).from_dict(self.sampler.describe(), self.sampler.n_params)

    def tell(self, result: TrialResult) -> bool:
        """Store `result` for result.trial_id; False if that trial was already finished."""
        stored = self.storage.finish_trial(result.trial_id, result, self.objective(result), time.time())
        if stored:
            self._n_finished += 1
        return stored
