"""Multi-fidelity search: asynchronous successive halving over trial durations ("rungs").

Every new parameter set is screened at the first rung's duration. Whenever a worker asks for work, a
parameter set in the top 1/eta of the completed trials of its rung that has not been promoted yet is
re-run at the next rung's duration (a new row: phase "promoted", parent = the row it re-runs) before
anything new is sampled, as long as that rung has promoted fewer than 1/eta of its completed trials
(at the end, each rung's best goes on past that quota).
The last rung is the full trial; a longer rung ranks before any shorter one for "best".

Samplers see only the first rung (FirstRungView): every parameter set they proposed has exactly one
first-rung row, so a model-based sampler (CMA-ES, TPE) learns from values of one duration, and the n-th
proposal of a run is the same with and without rungs (proposal n draws from the stream of set n, not of
row n, which promotions shift).

Promotions are decided from storage alone (which rows exist at which rung, with which parents), so a
restarted coordinator continues exactly where it stopped, and a lost lease re-issues the same row.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from itertools import pairwise
from typing import Any

import numpy as np
from spinefarm.protocol.errors import ConfigError
from spinefarm.protocol.messages import TrialStatus
from spinefarm.storage.base import BaseStorage


@dataclass(frozen=True)
class Rungs:
    """durations_s: increasing simulated durations, the last being the full trial; eta: keep 1/eta
    of each rung for the next."""

    durations_s: tuple[float, ...]
    eta: int = 3

    def __post_init__(self) -> None:
        d = tuple(float(x) for x in self.durations_s)
        object.__setattr__(self, "durations_s", d)
        if not d or any(not np.isfinite(x) or x <= 0 for x in d) or any(b <= a for a, b in pairwise(d)):
            raise ConfigError("rungs must be increasing positive durations", received=list(d),
                              expected="e.g. --rungs 10,30 (seconds; the last is the full trial)")
        if not isinstance(self.eta, int) or isinstance(self.eta, bool) or self.eta < 2:
            raise ConfigError("eta out of range", received=self.eta, expected="an integer >= 2")

    @property
    def top(self) -> int:
        return len(self.durations_s) - 1

    def to_dict(self) -> dict[str, Any]:
        return {"durations_s": list(self.durations_s), "eta": self.eta}

    @classmethod
    def from_dict(cls, d: dict[str, Any] | None) -> Rungs | None:
        return None if not d else cls(tuple(d["durations_s"]), int(d["eta"]))

    @classmethod
    def parse(cls, text: str, eta: int = 3) -> Rungs:
        try:
            durations = tuple(float(x) for x in text.split(",") if x.strip())
        except ValueError as exc:
            raise ConfigError("rungs are not numbers", received=text,
                              expected="comma-separated seconds, e.g. 10,30") from exc
        return cls(durations, eta)

    def promotion(self, storage: BaseStorage, sampling_done: bool = False) -> int | None:
        """The row to re-run at the next rung, or None: the best not-yet-promoted row among the top
        1/eta of some rung's complete rows (higher rungs first), while that rung has promoted fewer
        than 1/eta of its complete rows (so a search that keeps improving, as hill climbing does,
        promotes about 1/eta, not every row that was once in the top). Once no new parameter set will
        be sampled (`sampling_done`), each rung's best goes on past the quota too, so the best screened
        parameter set always reaches the full length."""
        cols = storage.columns()
        n = len(cols["trial_id"])
        if n == 0:
            return None
        rung, parent, obj = cols["rung"], cols["parent"], cols["objective"]
        complete = cols["status"] == TrialStatus.COMPLETE.stored
        promoted = cols["phase"] == b"promoted"
        promoted_from = set(parent[promoted].tolist())
        for r in range(self.top - 1, -1, -1):
            done = np.flatnonzero(complete & (rung == r) & np.isfinite(obj))
            keep = len(done) // self.eta
            if keep == 0:
                continue
            order = done[np.lexsort((done, -obj[done]))]  # best first; ties: the lower id
            if int(np.count_nonzero(promoted & (rung == r + 1))) >= keep:
                if not sampling_done:
                    continue
                order = order[:1]  # quota used: at the end only the rung's best still goes on
            for tid in order[:keep].tolist():
                if tid not in promoted_from:
                    return int(tid)
        return None


class FirstRungView:
    """What a sampler reads of a multi-fidelity run: the first-rung rows only, renumbered 0..k-1 in
    trial-id order (row k is the k-th parameter set sampled). `best_ids` ranks as the storage does
    (a longer rung first) and answers with the first-rung row of each best parameter set, so the
    hill climber's centre is still the best full-length gait."""

    def __init__(self, storage: BaseStorage) -> None:
        # made per proposal: no row is added while a sampler reads it
        self.storage = storage
        self.ids = np.flatnonzero(storage.columns()["rung"] == 0)

    def n_trials(self) -> int:
        return len(self.ids)

    def columns(self) -> dict[str, np.ndarray]:
        return {name: col[self.ids] for name, col in self.storage.columns().items()}

    def first_rung_row(self, trial_id: int) -> int:
        """The first-rung row a (possibly promoted) row re-runs, as a trial id."""
        cols = self.storage.columns()
        while cols["rung"][trial_id] > 0 and cols["parent"][trial_id] >= 0:
            trial_id = int(cols["parent"][trial_id])
        return trial_id

    def trial_id(self, index: int) -> int:
        """The storage trial id of view row `index`."""
        return int(self.ids[index])

    def best_ids(self, k: int) -> list[int]:
        out: list[int] = []
        for tid in self.storage.best_ids(k * 4 if k > 0 else 0):  # promotions repeat a set: ask for more
            row = self.first_rung_row(tid)
            index = int(np.searchsorted(self.ids, row))
            if index < len(self.ids) and self.ids[index] == row and index not in out:
                out.append(index)
            if len(out) == k:
                break
        return out


def describe_rungs(rungs: Rungs | None) -> dict[str, Any] | None:
    return None if rungs is None else asdict(rungs)
