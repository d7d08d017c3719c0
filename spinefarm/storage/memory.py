"""InMemoryStorage: the trial table in numpy arrays, for tests and as the HDF5 writer's mirror."""

from __future__ import annotations

import bisect
import math
from typing import Any

import numpy as np

from spinefarm.protocol.errors import StorageError
from spinefarm.protocol.states import JUDGED_VERDICTS, REFUTED_VERDICTS, TrialStatus
from spinefarm.storage.base import DISQUALIFYING_AUDITS, BaseStorage
from spinefarm.storage.episodes import EpisodeTable, rows_of
from spinefarm.storage.evaluations import EvaluationTable
from spinefarm.storage.ranking import (
    COT_OBJECTIVES,
    SCALED_OBJECTIVES,
    is_judged,
    judge_cots,
    ranked_value,
    screen_bias,
)
from spinefarm.storage.schema import RunMeta
from spinefarm.storage.table import TrialTable

_JUDGED_BY = ("verification", "verify_distance_m", "distance_m")   # what is_judged reads


class InMemoryStorage(BaseStorage):
    def __init__(self) -> None:
        self._meta: RunMeta | None = None
        self._table: TrialTable | None = None
        # Complete screened trials as (-rung, -screen's ranked value, id), kept sorted as results arrive:
        # best_ids is O(k), not a scan of the table per proposal (a longer multi-fidelity rung ranks first).
        # The judged ones (a few) apart, by their judged value: the screen's bias scales the others at each call
        # (storage.ranking), which keeps their order among themselves.
        self._ranking: list[tuple[int, float, int]] = []
        self._keys: dict[int, tuple[int, float, int]] = {}   # each screened trial's entry in _ranking
        self._judged: dict[int, tuple[int, float, int]] = {}
        self._bias: float | None = None   # screen_bias, until a verdict changes it
        self._episodes = EpisodeTable()
        self._evaluations = EvaluationTable()

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
        if "verification" in values:
            self._bias = None
        if "verification" in values or values.get("status") == TrialStatus.COMPLETE.stored:
            self._rerank(trial_id)   # a result, or a judged figure it now ranks by

    def _rank_key(self, cols: dict[str, np.ndarray], i: int) -> tuple[int, float, int]:
        objective = self.run_meta().objective
        judge_cot = math.nan   # read only for the few judged rows of a COT objective
        if objective in COT_OBJECTIVES and cols["verification"][i] in JUDGED_VERDICTS:
            judge_cot = judge_cots(self.evaluations(), np.array([i]))[0]
        value = ranked_value(objective, float(cols["objective"][i]), float(cols["distance_m"][i]),
                             cols["verification"][i], float(cols["verify_distance_m"][i]), float(cols["cot"][i]),
                             judge_cot)
        return -int(cols["rung"][i]), -value, i

    def _rerank(self, trial_id: int) -> None:
        old = self._keys.pop(trial_id, None)
        if old is not None:
            del self._ranking[bisect.bisect_left(self._ranking, old)]
        self._judged.pop(trial_id, None)
        cols = self.table.columns()
        if cols["status"][trial_id] == TrialStatus.COMPLETE.stored and math.isfinite(cols["objective"][trial_id]):
            key = self._rank_key(cols, trial_id)
            if is_judged({c: cols[c][trial_id: trial_id + 1] for c in _JUDGED_BY}, self.run_meta().objective)[0]:
                self._judged[trial_id] = key
            else:
                self._keys[trial_id] = key
                bisect.insort(self._ranking, key)

    def _rebuild_ranking(self) -> None:
        """Rank a table loaded in one go (resume, read-only open) with the scanning helper."""
        cols = self.table.columns()
        # every complete ranked row: a row an audit disputes or a quarantine marks may be cleared later (best_ids
        # filters by the verdicts at each call)
        done = np.flatnonzero((cols["status"] == TrialStatus.COMPLETE.stored) & np.isfinite(cols["objective"]))
        judged = is_judged({c: cols[c][done] for c in _JUDGED_BY}, self.run_meta().objective)
        self._keys = {int(i): self._rank_key(cols, int(i)) for i in done[~judged]}
        self._judged = {int(i): self._rank_key(cols, int(i)) for i in done[judged]}
        self._ranking = sorted(self._keys.values())
        self._bias = None

    def best_ids(self, k: int) -> list[int]:
        if k <= 0:
            return []
        cols = self.table.columns()
        if self._bias is None:
            self._bias = screen_bias(cols)
        bias = self._bias if self.run_meta().objective in SCALED_OBJECTIVES else 1.0
        verification, audit = cols["verification"], cols["audit"]
        screened = []
        for rung, neg_value, i in self._ranking:  # as BaseStorage.best_ids: not refuted by the judge or an audit
            if verification[i] not in REFUTED_VERDICTS and audit[i] not in DISQUALIFYING_AUDITS:
                screened.append((rung, neg_value * bias if neg_value < 0 else neg_value, i))
                if len(screened) == k:
                    break
        judged = [key for i, key in self._judged.items() if audit[i] not in DISQUALIFYING_AUDITS]
        return [i for *_, i in sorted(screened + judged)[:k]]

    def n_trials(self) -> int:
        return self.table.n

    def add_evaluation(self, row: dict[str, Any]) -> None:
        self._writable()
        self._check_id(int(row["trial_id"]))
        self._evaluations.append(row)
        if self.table.columns()["status"][int(row["trial_id"])] == TrialStatus.COMPLETE.stored:
            self._rerank(int(row["trial_id"]))  # a judge's COT a COT objective ranks by

    def evaluations(self) -> dict[str, np.ndarray]:
        return self._evaluations.columns()

    def _add_episodes(self, trial_id: int, episodes: tuple) -> None:
        self._episodes.append(trial_id, episodes)

    def episodes(self, trial_id: int | None = None) -> dict[str, np.ndarray]:
        cols = self._episodes.columns()
        return cols if trial_id is None else rows_of(cols, trial_id)

    def columns(self) -> dict[str, np.ndarray]:
        return self.table.columns()
