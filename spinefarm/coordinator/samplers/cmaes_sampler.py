"""CmaEsSampler (`cmaes`): CMA-ES with IPOP restarts (the `cmaes` library), in the unit cube.

The model is replayed from storage: complete and failed trials of the finished prefix (see
FinishedPrefix) are told in trial-id order, `population_size` at a time, as the library requires.
The first distribution is centred on `mean0` (the first `--enqueue`d set, so a search can refine a known
gait) or on the cube's centre. When the library's stopping test fires, CMA-ES restarts from a uniform
random mean with the population multiplied by `population_growth` (IPOP-CMA-ES). Trial n samples from the current
distribution with the library's generator reseeded from (run seed, n), so a proposal is fixed by
storage and trial number, and a restarted coordinator rebuilds the same distribution.
Failed trials and non-finite objectives rank below every complete trial.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from spinefarm.coordinator.samplers.base import CMAES, BaseSampler, FinishedPrefix, Proposal, trial_seed32
from spinefarm.protocol.errors import ConfigError, check_range
from spinefarm.protocol.states import TrialStatus
from spinefarm.storage.base import BaseStorage

_FAILED_VALUE = 1e30  # minimised: a failed trial is worse than any complete one


def _unit_point(values: object) -> tuple[float, ...] | None:
    """A point of the unit cube as a tuple (None stays None: the cube's centre)."""
    if values is None:
        return None
    point = tuple(float(v) for v in values)  # type: ignore[attr-defined]
    outside = [v for v in point if not 0.0 <= v <= 1.0]
    if outside:
        raise ConfigError("cmaes's start point is outside the unit cube", received=outside[:3],
                          expected="values in [0, 1]")
    return point


class CmaEsSampler(BaseSampler):
    name = "cmaes"
    settings = (("sigma0", float), ("population_size", int), ("population_growth", float), ("mean0", _unit_point))

    def __init__(self, n_params: int, seed: int, *, sigma0: float = 0.3, population_size: int | None = None,
                 population_growth: float = 2.0, mean0: Sequence[float] | None = None) -> None:
        super().__init__(n_params, seed)
        if n_params < 2:
            raise ConfigError("cmaes needs at least 2 parameters", received=n_params, expected=">= 2")
        check_range("sigma0", sigma0, 0.0, 1.0, low_inclusive=False)
        check_range("population_growth", population_growth, 1.0)
        self.sigma0 = float(sigma0)
        self.population_size = int(population_size or 4 + math.floor(3 * math.log(n_params)))
        check_range("population_size", self.population_size, 2)
        self.population_growth = float(population_growth)
        self.mean0 = _unit_point(mean0)
        if self.mean0 is not None and len(self.mean0) != n_params:
            raise ConfigError("cmaes's start point does not fit the run's space", received=f"{len(self.mean0)} values",
                              expected=f"{n_params} values in [0, 1]")
        self._reset()

    def _reset(self) -> None:
        self._prefix = FinishedPrefix()
        self.restarts = 0
        self._buffer: list[tuple[np.ndarray, float]] = []
        mean = np.full(self.n_params, 0.5) if self.mean0 is None else np.array(self.mean0)
        self._cma = self._new_cma(mean, self.population_size)

    def _new_cma(self, mean: np.ndarray, popsize: int) -> Any:
        from cmaes import CMA

        bounds = np.tile([0.0, 1.0], (self.n_params, 1))
        return CMA(mean=mean, sigma=self.sigma0, bounds=bounds, population_size=popsize,
                   seed=trial_seed32(self.seed, self.restarts, salt=1))

    def _restart(self) -> None:
        self.restarts += 1
        popsize = int(round(self.population_size * self.population_growth**self.restarts))
        mean = np.random.default_rng([self.seed, self.restarts, 2]).random(self.n_params)  # not a trial's stream
        self._cma = self._new_cma(mean, popsize)
        self._buffer = []

    def _learn(self, storage: BaseStorage, limit: int) -> None:
        if limit < self._prefix.end:  # asked about an earlier trial: learn again from the start
            self._reset()
        end = FinishedPrefix.scan(storage, self._prefix.end, limit)
        cols = storage.columns()
        for i in range(self._prefix.end, end):
            ok = cols["status"][i] == TrialStatus.COMPLETE.stored and math.isfinite(float(cols["objective"][i]))
            value = -float(cols["objective"][i]) if ok else _FAILED_VALUE
            self._buffer.append((np.array(cols["params_unit"][i], dtype=float), value))
            if len(self._buffer) == self._cma.population_size:
                self._cma.tell(self._buffer)
                self._buffer = []
                if self._cma.should_stop():
                    self._restart()
        self._prefix.end = end

    def propose(self, trial_id: int, storage: BaseStorage) -> Proposal:
        self._learn(storage, min(trial_id, storage.n_trials()))
        self._cma.reseed_rng(trial_seed32(self.seed, trial_id))
        x = np.clip(self._cma.ask(), 0.0, 1.0)
        return Proposal(x, CMAES, -1)

