"""Which evaluation comes next on a run's fidelity ladder: the trial-scheduler seam.

A BaseTrialScheduler decides, from storage alone, whether the next row re-runs a stored parameter set
at a higher rung (a promotion) or samples a new one, when the search is done, and what a sampler
reads. Two schedulers, in the spirit of Ray Tune's TrialScheduler and Optuna's pruners:

- PlainTrialScheduler: every parameter set is one evaluation at the ladder's one rung.
- HalvingTrialScheduler: asynchronous successive halving over the ladder. Every new parameter set is
  screened at the first rung. Whenever a worker asks for work, a parameter set in the top 1/eta of the
  completed rows of its rung that has not been promoted yet is re-run at the next rung (a new row:
  phase "promoted", parent = the row it re-runs) before anything new is sampled, as long as that rung
  has promoted fewer than 1/eta of its completed rows (at the end, each rung's best goes on past that
  quota). A longer rung ranks before any shorter one for "best". Samplers see only the first rung
  (FirstRungView): every parameter set has exactly one first-rung row, so a model-based sampler learns
  from values of one duration, and proposal n is the same with and without rungs.

A promotion is offered first to the worker that ran the set's last rung (Asker): that worker may have kept the
rung's end and go on from it instead of simulating the rung again (worker.trial.continued; the same bits either
way). While new parameter sets are still being sampled, a promotion whose last rung another live worker ran waits
for that worker (the asker samples a new set instead); once sampling is done, or that worker is gone, whoever
asks takes it and simulates it from the start.

Everything is decided from which rows exist at which rung with which parents, so a restarted
coordinator continues exactly where it stopped, and a lost lease re-issues the same row.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from spinefarm.protocol.errors import ConfigError
from spinefarm.protocol.settings import PROMOTED, Rung, RunSettings
from spinefarm.protocol.states import TrialStatus
from spinefarm.storage.base import BaseStorage

_PROMOTED = PROMOTED.encode()


def parse_rungs(text: str) -> tuple[float, ...]:
    """`--rungs 10,30` as durations in seconds (checked by RunSettings)."""
    try:
        return tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError as exc:
        raise ConfigError("rungs are not numbers", received=text,
                          expected="comma-separated seconds, e.g. 10,30") from exc


@dataclass(frozen=True)
class Asker:
    """The worker asking for work, for the choice of a promotion (see the module). waits_for(worker): whether a
    promotion whose last rung `worker` ran may wait for it (it is alive and may go on from that rung's end)."""

    worker_id: str
    waits_for: Callable[[str], bool]


class BaseTrialScheduler:
    """Called by the study under the coordinator's lock. `promotion` when a worker asks for work
    (before anything is sampled), `sampler_view` before each proposal, `done` whenever the run's state
    is asked for; nothing is kept between calls that storage cannot rebuild."""

    def __init__(self, settings: RunSettings) -> None:
        self.settings = settings

    @property
    def top(self) -> int:
        return self.settings.top

    def duration_s(self, rung: int) -> float:
        """Simulated seconds of rung `rung` (NaN: the run's own duration)."""
        d = self.settings.ladder[rung].duration_s
        return math.nan if d is None else d

    def rung(self, index: int) -> Rung:
        return self.settings.ladder[index]

    def planned(self, budget: int) -> int:
        return self.settings.planned_evaluations(budget)

    def n_sampled(self, storage: BaseStorage) -> int:
        """New parameter sets sampled so far."""
        return storage.n_trials()

    def promotion(self, storage: BaseStorage, sampling_done: bool = False, asker: Asker | None = None) -> int | None:
        """The row to re-run at its next rung, or None (sample a new set)."""
        return None

    def sampler_view(self, storage: BaseStorage) -> Any:
        """What a sampler reads: storage itself, or a view with the same reading methods."""
        return storage

    def parent_id(self, view: Any, parent: int) -> int:
        """A proposal's parent (an index of the view) as a storage trial id."""
        return parent

    def done(self, storage: BaseStorage, budget: int, n_finished: int) -> bool:
        return n_finished >= budget


class PlainTrialScheduler(BaseTrialScheduler):
    """Every parameter set evaluated once, at the ladder's last rung."""


class HalvingTrialScheduler(BaseTrialScheduler):
    """Asynchronous successive halving over the ladder, keeping 1/eta of each rung (see the module)."""

    @property
    def eta(self) -> int:
        return self.settings.eta

    def n_sampled(self, storage: BaseStorage) -> int:
        return int(storage.count_rung(0))

    def duration_s(self, rung: int) -> float:
        return float(self.settings.ladder[rung].duration_s)

    def sampler_view(self, storage: BaseStorage) -> FirstRungView:
        return FirstRungView(storage)

    def parent_id(self, view: Any, parent: int) -> int:
        return view.trial_id(parent) if parent >= 0 else -1

    def done(self, storage: BaseStorage, budget: int, n_finished: int) -> bool:
        if self.n_sampled(storage) < budget or n_finished < storage.n_trials():
            return False
        return self.promotion(storage, True) is None

    def promotion(self, storage: BaseStorage, sampling_done: bool = False, asker: Asker | None = None) -> int | None:
        """The first of the promotable rows (`promotable`); with an asker, the first whose last rung it ran, else the
        first that need not wait for the worker that ran it (see the module)."""
        rows = self.promotable(storage, sampling_done)
        if asker is None:
            return next(rows, None)
        ran_by = storage.columns()["worker_id"]
        own = asker.worker_id.encode("utf-8", "replace")[:64]  # as storage keeps it
        first = None
        for tid in rows:
            if ran_by[tid] == own:
                return tid
            if first is None and (sampling_done or not asker.waits_for(ran_by[tid].decode("utf-8", "replace"))):
                first = tid
        return first

    def promotable(self, storage: BaseStorage, sampling_done: bool) -> Iterator[int]:
        """The rows due to be re-run at their next rung, in order: the best not-yet-promoted rows among the top
        1/eta of each rung's complete rows (higher rungs first), while that rung has promoted fewer than 1/eta of
        its complete rows (so a search that keeps improving, as hill climbing does, promotes about 1/eta, not
        every row that was once in the top). Once no new parameter set will be sampled (`sampling_done`), each
        rung's best goes on past the quota too, so the best screened parameter set always reaches the full
        length."""
        cols = storage.columns()
        if len(cols["trial_id"]) == 0:
            return
        rung, obj = cols["rung"], cols["objective"]
        complete = cols["status"] == TrialStatus.COMPLETE.stored
        promoted = cols["phase"] == _PROMOTED
        promoted_from = set(cols["parent"][promoted].tolist())
        for r in range(self.top - 1, -1, -1):
            done = np.flatnonzero(complete & (rung == r) & np.isfinite(obj))
            keep = len(done) // self.eta
            if len(done) == 0 or (keep == 0 and not sampling_done):
                continue
            order = done[np.lexsort((done, -obj[done]))]  # best first; ties: the lower id
            if keep == 0 or int(np.count_nonzero(promoted & (rung == r + 1))) >= keep:
                if not sampling_done:
                    continue
                # quota used, or a rung of fewer than eta rows: at the end only the rung's best still goes on
                order, keep = order[:1], 1
            for tid in order[:keep].tolist():
                if tid not in promoted_from:
                    yield int(tid)


def trial_scheduler(settings: RunSettings) -> BaseTrialScheduler:
    """The stored run's scheduler."""
    cls = HalvingTrialScheduler if settings.scheduler == "halving" else PlainTrialScheduler
    return cls(settings)


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
