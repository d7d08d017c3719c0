"""BaseSampler: proposes the unit-cube vector of trial n from what storage holds."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from spinefarm.protocol.states import TrialStatus
from spinefarm.storage.base import BaseStorage
from spinefarm.storage.ranking import learned_columns

MONTE_CARLO = "monte_carlo"
GAUSSIAN = "gaussian"
CMAES = "cmaes"
TPE = "tpe"


@dataclass(frozen=True)
class Proposal:
    """params_unit: (n_params,) in [0, 1]; parent: centre trial id, -1 for none."""

    params_unit: np.ndarray
    phase: str
    parent: int


def trial_rng(seed: int, trial_id: int) -> np.random.Generator:
    """The random stream of one trial: the run seed and the trial number fix every draw."""
    return np.random.default_rng([seed, trial_id])


def trial_seed32(seed: int, trial_id: int, salt: int = 0) -> int:
    """A 32-bit seed for a library's own generator, fixed by the run seed and the trial number."""
    return int(np.random.SeedSequence([seed, trial_id, salt]).generate_state(1)[0])


class BaseSampler:
    """Called by the study once per new trial, in trial-id order, from one thread.

    `propose(trial_id, storage)` may read the storage (finished trials, best so far) but keeps no
    state of its own that storage cannot rebuild, so a resumed run samples as it would have.
    In a multi-fidelity run `storage` is the first rung's view (coordinator.ladder.rungs.FirstRungView):
    trial n is then the n-th parameter set, and every row has the same duration.
    `name` is the registry name (`--sampler NAME`); `from_dict(describe())` rebuilds the sampler.
    """

    name: ClassVar[str] = ""
    # the keyword settings of __init__, stored with the run and read back by from_dict: (name, type)
    settings: ClassVar[tuple[tuple[str, type], ...]] = ()

    def __init__(self, n_params: int, seed: int) -> None:
        self.n_params = n_params
        self.seed = seed

    def propose(self, trial_id: int, storage: BaseStorage) -> Proposal:
        raise NotImplementedError

    def describe(self) -> dict[str, Any]:
        """JSON-able settings, stored with the run."""
        return {"name": self.name, "kind": type(self).__name__, "seed": self.seed,
                **{k: getattr(self, k) for k, _ in self.settings}}

    @classmethod
    def from_dict(cls, d: dict[str, Any], n_params: int) -> BaseSampler:
        """Rebuild from describe() output (the stored run's `sampler` attribute)."""
        # a setting added later is missing from older files: the sampler's default then
        return cls(n_params, int(d["seed"]), **{k: kind(d[k]) for k, kind in cls.settings if k in d})


class FinishedPrefix:
    """The trials a model-based sampler learns from: every finished trial before the first unfinished one.

    Results arrive out of order; learning only from the finished prefix (ids 0..p-1, none waiting)
    makes what a sampler has learnt a function of storage alone, replayed in trial-id order, and it
    only ever grows, so a sampler extends its model instead of rebuilding it. A slow trial holds the
    model back until it finishes (or its lease expires and it is re-issued).
    """

    def __init__(self) -> None:
        self.end = 0

    @staticmethod
    def scan(storage: BaseStorage, start: int, limit: int) -> int:
        """First waiting id in [start, limit), or limit."""
        status = storage.columns()["status"][start:limit]
        waiting = np.flatnonzero(status == TrialStatus.WAITING.stored)
        return start + int(waiting[0]) if waiting.size else limit


class LearnedView:
    """What a sampler reads: the study's view of storage, with each row's figure as a sampler should learn it
    (storage.ranking.learned_columns: a quarantined worker's forged value is not learnt, its re-run's is)."""

    def __init__(self, view: Any, objective_name: str) -> None:
        self._view, self._objective_name = view, objective_name

    def columns(self) -> dict[str, np.ndarray]:
        cols = self._view.columns()
        amended = learned_columns(cols, self._objective_name)
        return {**cols, **amended} if amended else cols

    def __getattr__(self, name: str) -> Any:
        return getattr(self._view, name)
