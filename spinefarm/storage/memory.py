"""InMemoryStorage: the trial table in numpy arrays, for tests and as the HDF5 writer's mirror."""

from __future__ import annotations

import bisect
import math
from typing import Any

import numpy as np

from spinefarm.protocol.errors import StorageError
from spinefarm.protocol.states import TrialStatus, Verification
from spinefarm.storage.base import DISQUALIFYING_AUDITS, BaseStorage
from spinefarm.storage.episodes import EpisodeTable, rows_of
from spinefarm.storage.schema import RunMeta
from spinefarm.storage.table import TrialTable


class InMemoryStorage(BaseStorage):
    def __init__(self) -> None:
        self._meta: RunMeta | None = None
        self._table: TrialTable | None = None
        # Complete trials as (-rung, -objective, id), kept sorted as results arrive: best_ids is O(k),
        # not a scan of the table per proposal (a longer multi-fidelity rung ranks first).
        self._ranking: list[tuple[int, float, int]] = []
        self._episodes = EpisodeTable()

    def create_run(self, meta: RunMeta) -> None:
        if self._meta is not None:
            raise StorageError("run already created", received=meta.run_id, expected="one run per store")
        self._meta = meta
        self._table = TrialTable(meta.n_params)

    def run_meta(self) -> RunMeta:
        if self._meta is None:
            raise StorageError("no run in this store", expected="create_run() first")
        return self._meta

    @property
    def table(self) -> TrialTable:
        if self._table is None:
            raise StorageError("no run in this store", expected="create_run() first")
        return self._table

    def _append(self, values: dict[str, Any]) -> None:
        self.table.append_row(values)

    def _update(self, trial_id: int, values: dict[str, Any]) -> None:
        self.table.set_row(trial_id, values)
        if values.get("status") == TrialStatus.COMPLETE.stored and math.isfinite(values.get("objective", math.nan)):
            rung = int(self.table.columns()["rung"][trial_id])
            bisect.insort(self._ranking, (-rung, -float(values["objective"]), trial_id))

    def _rebuild_ranking(self) -> None:
        """Rank a table loaded in one go (resume, read-only open) with the scanning helper."""
        cols = self.table.columns()
        # every complete ranked row: a row an audit disputes or a quarantine marks may be cleared later (best_ids
        # filters by the verdicts at each call)
        done = np.flatnonzero((cols["status"] == TrialStatus.COMPLETE.stored) & np.isfinite(cols["objective"]))
        self._ranking = sorted((-int(cols["rung"][i]), -float(cols["objective"][i]), int(i)) for i in done)

    def best_ids(self, k: int) -> list[int]:
        if k <= 0:
            return []
        cols = self.table.columns()
        verification, audit = cols["verification"], cols["audit"]
        out = []
        for *_, i in self._ranking:  # as BaseStorage.best_ids: not refuted by the judge or an audit
            if verification[i] != Verification.NOT_REPRODUCED.stored and audit[i] not in DISQUALIFYING_AUDITS:
                out.append(i)
                if len(out) == k:
                    break
        return out

    def n_trials(self) -> int:
        return self.table.n

    def _add_episodes(self, trial_id: int, episodes: tuple) -> None:
        self._episodes.append(trial_id, episodes)

    def episodes(self, trial_id: int | None = None) -> dict[str, np.ndarray]:
        cols = self._episodes.columns()
        return cols if trial_id is None else rows_of(cols, trial_id)

    def columns(self) -> dict[str, np.ndarray]:
        return self.table.columns()
