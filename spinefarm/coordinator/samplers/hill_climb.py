"""GaussianHillClimbSampler (`paper`): uniform for the first trials, then Gaussian steps around the best.

After `startup_trials` trials (the Monte Carlo phase) each trial is drawn around a centre chosen
among the `top_k` best complete trials stored so far: x = clip(centre + sigma * N(0, I), 0, 1).
The centre is read from storage, so it moves as soon as a better result is stored (hill climbing)
and a restarted coordinator continues from the same centre. Before any trial has completed, past the
startup trials, the centre is the first stored trial that has not failed (an `--enqueue`d start still
running, say): a climb with no Monte Carlo phase never draws a uniform sample once it has a start.
"""

from __future__ import annotations

import numpy as np

from spinefarm.coordinator.samplers.base import GAUSSIAN, MONTE_CARLO, BaseSampler, Proposal, trial_rng
from spinefarm.protocol.errors import check_range
from spinefarm.protocol.states import TrialStatus
from spinefarm.storage.base import BaseStorage


class GaussianHillClimbSampler(BaseSampler):
    name = "paper"
    settings = (("sigma", float), ("top_k", int), ("startup_trials", int))

    def __init__(self, n_params: int, seed: int, *, sigma: float = 0.005, top_k: int = 1,
                 startup_trials: int = 0) -> None:
        super().__init__(n_params, seed)
        check_range("sigma", sigma, 0.0, 1.0, low_inclusive=False)
        check_range("top_k", top_k, 1)
        check_range("startup_trials", startup_trials, 0)
        self.sigma = float(sigma)
        self.top_k = int(top_k)
        self.startup_trials = int(startup_trials)

    def propose(self, trial_id: int, storage: BaseStorage) -> Proposal:
        rng = trial_rng(self.seed, trial_id)
        uniform = rng.random(self.n_params)  # drawn first so both phases share one stream layout
        centres = self._centres(trial_id, storage) if trial_id >= self.startup_trials else []
        if not centres:
            return Proposal(uniform, MONTE_CARLO, -1)
        parent = centres[int(rng.integers(len(centres)))]
        centre = storage.columns()["params_unit"][parent]
        step = self.sigma * rng.standard_normal(self.n_params)
        return Proposal(np.clip(centre + step, 0.0, 1.0), GAUSSIAN, parent)

    def _centres(self, trial_id: int, storage: BaseStorage) -> list[int]:
        best = storage.best_ids(self.top_k)
        if best:
            return best
        # nothing complete yet: the first stored trial that may still succeed
        status = storage.columns()["status"][:trial_id]
        alive = np.flatnonzero(status != TrialStatus.FAILED.stored)
        return [int(alive[0])] if alive.size else []
