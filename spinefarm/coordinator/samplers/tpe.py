"""TpeSampler (`tpe`): Optuna's TPE through ask/tell on an in-memory study rebuilt from storage.

The study holds the finished prefix of the run (see FinishedPrefix) added in trial-id order;
trial n is asked with a TPESampler seeded from (run seed, n), so a proposal is fixed by storage
and trial number. The asked Optuna trial is closed as failed at once (TPE ignores failed trials),
so the study a restarted coordinator rebuilds samples alike. With the `pareto` objective the study
is multi-objective: speed maximised, COT minimised (Optuna's multi-objective TPE); otherwise it
maximises the stored objective. Failed trials are left out, as every sampler ignores them.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np

from spinefarm.coordinator.samplers.base import TPE, BaseSampler, FinishedPrefix, Proposal, trial_seed32
from spinefarm.protocol.errors import check_range
from spinefarm.protocol.states import TrialStatus
from spinefarm.storage.base import BaseStorage

_COT_CAP = 1e6  # no motion gives COT = inf; Optuna needs finite values


class TpeSampler(BaseSampler):
    name = "tpe"
    settings = (("startup_trials", int), ("multivariate", bool), ("multi_objective", bool))

    def __init__(self, n_params: int, seed: int, *, startup_trials: int = 10, multivariate: bool = True,
                 multi_objective: bool = False) -> None:
        super().__init__(n_params, seed)
        check_range("startup_trials", startup_trials, 0)
        self.startup_trials = int(startup_trials)
        self.multivariate = bool(multivariate)
        self.multi_objective = bool(multi_objective)
        self._names = [f"u{i}" for i in range(n_params)]
        self._study: Any = None

    def _reset(self) -> None:
        import optuna

        optuna.logging.set_verbosity(optuna.logging.WARNING)
        self._prefix = FinishedPrefix()
        self._dists = {n: optuna.distributions.FloatDistribution(0.0, 1.0) for n in self._names}
        directions = ["maximize", "minimize"] if self.multi_objective else ["maximize"]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
            tpe = optuna.samplers.TPESampler(seed=0, n_startup_trials=self.startup_trials,
                                             multivariate=self.multivariate)
        self._study = optuna.create_study(directions=directions, sampler=tpe)

    def _values(self, cols: dict[str, np.ndarray], i: int) -> list[float] | None:
        if cols["status"][i] != TrialStatus.COMPLETE.stored:
            return None
        if self.multi_objective:
            speed, cot = float(cols["speed_cm_s"][i]), float(cols["cot"][i])
            if not math.isfinite(speed) or math.isnan(cot):
                return None
            return [speed, min(cot, _COT_CAP)]
        value = float(cols["objective"][i])
        return [value] if math.isfinite(value) else None

    def _learn(self, storage: BaseStorage, limit: int) -> None:
        import optuna

        if self._study is None or limit < self._prefix.end:
            self._reset()
        end = FinishedPrefix.scan(storage, self._prefix.end, limit)
        cols = storage.columns()
        for i in range(self._prefix.end, end):
            values = self._values(cols, i)
            if values is None:
                continue
            params = dict(zip(self._names, (float(v) for v in cols["params_unit"][i]), strict=True))
            self._study.add_trial(optuna.trial.create_trial(params=params, distributions=self._dists,
                                                            values=values))
        self._prefix.end = end

    def propose(self, trial_id: int, storage: BaseStorage) -> Proposal:
        import optuna

        self._learn(storage, min(trial_id, storage.n_trials()))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
            self._seed_tpe(trial_seed32(self.seed, trial_id))
            trial = self._study.ask(self._dists)
        params = trial.params  # a copy per access
        x = np.array([params[n] for n in self._names], dtype=float)
        self._study.tell(trial, state=optuna.trial.TrialState.FAIL)
        return Proposal(np.clip(x, 0.0, 1.0), TPE, -1)

    def _seed_tpe(self, seed: int) -> None:
        """Trial n draws from a generator seeded by (run seed, n). One TPE sampler is kept for the run and
        reseeded, because a new one recomputes the search space over every stored trial (0.13 s per
        proposal at 300 trials of 202 parameters); the model itself is rebuilt from the study each time."""
        import optuna

        tpe = self._study.sampler
        try:
            tpe._rng.rng.seed(seed)
            tpe._random_sampler._rng.rng.seed(seed)
        except AttributeError:  # an Optuna without these generators: a fresh sampler per proposal
            self._study.sampler = optuna.samplers.TPESampler(seed=seed, n_startup_trials=self.startup_trials,
                                                             multivariate=self.multivariate)

