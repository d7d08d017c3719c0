"""Study: ask/tell over a storage and a sampler, with a trial budget and an objective."""

from __future__ import annotations

import time
from collections.abc import Callable

from coordinator.samplers.base import BaseSampler
from protocol.messages import TrialResult
from protocol.params import ParamSpace
from storage.base import BaseStorage


def trial_seed(run_seed: int, trial_id):
    """Seed of trial `trial_id` (an int or an integer array) in a run seeded with `run_seed`."""
    return (run_seed * 1_000_003 + trial_id) % (2**31 - 1)


class Study:
    """`ask` samples and records the next trial; `tell` stores a result once.

    Trial ids are dense row numbers; the seed of trial n is derived from the run seed and n.
    """

    def __init__(self, storage: BaseStorage, sampler: BaseSampler, space: ParamSpace, budget: int,
                 objective: Callable[[TrialResult], float], seed: int) -> None:
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
    def done(self) -> bool:
        return self._n_finished >= self.budget

    def trial_seed(self, trial_id: int) -> int:
        return trial_seed(self.seed, trial_id)

    def ask(self) -> int | None:
        """Sample and record the next trial; None once the budget is allotted."""
        tid = self.storage.n_trials()
        if tid >= self.budget:
            return None
        p = self.sampler.propose(tid, self.storage)
        self.storage.add_trial(tid, p.params_unit, self.space.from_unit(p.params_unit), p.phase, p.parent,
                               self.trial_seed(tid))
        return tid

    def tell(self, result: TrialResult) -> bool:
        """Store `result` for result.trial_id; False if that trial was already finished."""
        stored = self.storage.finish_trial(result.trial_id, result, self.objective(result), time.time())
        if stored:
            self._n_finished += 1
        return stored
