"""Study: ask/tell over a storage and a sampler, with a trial budget and an objective."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np
from spinefarm.coordinator.fidelity import FirstRungView, Rungs
from spinefarm.coordinator.samplers.base import BaseSampler
from spinefarm.protocol.messages import TrialResult
from spinefarm.protocol.params import ParamSpace
from spinefarm.storage.base import BaseStorage
from spinefarm.storage.schema import planned_evaluations

PROMOTED = "promoted"


def trial_seed(run_seed: int, trial_id):
    """Seed of trial `trial_id` (an int or an integer array) in a run seeded with `run_seed`."""
    return (run_seed * 1_000_003 + trial_id) % (2**31 - 1)


class Study:
    """`ask` samples and records the next trial; `tell` stores a result once.

    Trial ids are dense row numbers; the seed of trial n is derived from the run seed and n.
    """

    def __init__(self, storage: BaseStorage, sampler: BaseSampler, space: ParamSpace, budget: int,
                 objective: Callable[[TrialResult], float], seed: int, rungs: Rungs | None = None) -> None:
        """rungs: multi-fidelity screening; `budget` then counts new parameter sets (the first rung),
        and promotions to longer rungs come on top."""
        self.rungs = rungs
        self.storage = storage
        self.sampler = sampler
        self.space = space
        self.budget = budget
        self.objective = objective
        self.seed = seed
        self._n_finished = sum(v for k, v in storage.counts().items() if k != "waiting")

    @property
    def n_asked(self) -> int:
        return self.storage.n_trials()

    @property
    def n_finished(self) -> int:
        return self._n_finished

    @property
    def n_sampled(self) -> int:
        """New parameter sets sampled so far (promotions re-run earlier ones)."""
        if self.rungs is None:
            return self.storage.n_trials()
        return int(self.storage.count_rung(0))

    @property
    def planned(self) -> int:
        """Evaluations the run expects: the budget, plus about budget / eta^k promotions to rung k."""
        return planned_evaluations(self.budget, None if self.rungs is None else self.rungs.to_dict())

    @property
    def done(self) -> bool:
        if self.rungs is None:
            return self._n_finished >= self.budget
        if self.n_sampled < self.budget or self._n_finished < self.storage.n_trials():
            return False
        return self.rungs.promotion(self.storage, True) is None

    def trial_seed(self, trial_id: int) -> int:
        return trial_seed(self.seed, trial_id)

    def ask(self) -> int | None:
        """Sample and record the next trial (first a promotion to a longer rung, if one is due);
        None once the budget is allotted."""
        tid = self.storage.n_trials()
        if self.rungs is not None:
            source = self.rungs.promotion(self.storage, self.n_sampled >= self.budget)
            if source is not None:
                row = self.storage.trial(source)
                unit = np.asarray(row.params_unit)
                self.storage.add_trial(tid, unit, self.space.from_unit(unit), PROMOTED, source,
                                       self.trial_seed(tid), row.rung + 1, self.rungs.durations_s[row.rung + 1])
                return tid
            if self.n_sampled >= self.budget:
                return None
        elif tid >= self.budget:
            return None
        if self.rungs is None:
            p = self.sampler.propose(tid, self.storage)
            parent, duration = p.parent, math.nan
        else:  # the sampler sees the first rung only: proposal k is the k-th parameter set
            view = FirstRungView(self.storage)
            p = self.sampler.propose(view.n_trials(), view)
            parent, duration = (view.trial_id(p.parent) if p.parent >= 0 else -1), self.rungs.durations_s[0]
        self.storage.add_trial(tid, p.params_unit, self.space.from_unit(p.params_unit), p.phase, parent,
                               self.trial_seed(tid), 0, duration)
        return tid

    def tell(self, result: TrialResult) -> bool:
        """Store `result` for result.trial_id; False if that trial was already finished."""
        stored = self.storage.finish_trial(result.trial_id, result, self.objective(result), time.time())
        if stored:
            self._n_finished += 1
        return stored
