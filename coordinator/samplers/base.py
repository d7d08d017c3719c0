"""BaseSampler: proposes the unit-cube vector of trial n from what storage holds."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from storage.base import BaseStorage

MONTE_CARLO = "monte_carlo"
GAUSSIAN = "gaussian"


@dataclass(frozen=True)
class Proposal:
    """params_unit: (n_params,) in [0, 1]; parent: centre trial id, -1 for none."""

    params_unit: np.ndarray
    phase: str
    parent: int


def trial_rng(seed: int, trial_id: int) -> np.random.Generator:
    """The random stream of one trial: the run seed and the trial number fix every draw."""
    return np.random.default_rng([seed, trial_id])


class BaseSampler:
    """Called by the study once per new trial, in trial-id order, from one thread.

    `propose(trial_id, storage)` may read the storage (finished trials, best so far) but keeps no
    state of its own that storage cannot rebuild, so a resumed run samples as it would have.
    """

    def __init__(self, n_params: int, seed: int) -> None:
        self.n_params = n_params
        self.seed = seed

    def propose(self, trial_id: int, storage: BaseStorage) -> Proposal:
        raise NotImplementedError

    def describe(self) -> dict[str, Any]:
        """JSON-able settings, stored with the run."""
        return {"kind": type(self).__name__, "seed": self.seed}
