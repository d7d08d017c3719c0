"""RandomSampler: the Monte Carlo phase, uniform in the unit cube."""

from __future__ import annotations

from spinefarm.coordinator.samplers.base import MONTE_CARLO, BaseSampler, Proposal, trial_rng
from spinefarm.storage.base import BaseStorage


class RandomSampler(BaseSampler):
    name = "random"

    def propose(self, trial_id: int, storage: BaseStorage) -> Proposal:
        return Proposal(trial_rng(self.seed, trial_id).random(self.n_params), MONTE_CARLO, -1)
