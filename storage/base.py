"""BaseStorage: the primitives a results store implements, and helpers built only on them."""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from protocol.errors import StorageError
from protocol.messages import TrialResult, TrialStatus
from storage.schema import RunMeta, TrialRecord


class BaseStorage:
    """One run's metadata and trial table.

    Call order: `create_run` once for a new run (or open an existing one), then `add_trial` when the
    sampler proposes trial n (ids are dense, 0, 1, 2, ...), `finish_trial` when its result arrives,
    `flush` at a bounded interval (what was flushed survives a crash), `close` at the end.
    Readers use `columns`, `run_meta` and the helpers; a read-only storage refuses writes.
    """

    read_only = False

    # --- primitives -------------------------------------------------------------------------------
    def create_run(self, meta: RunMeta) -> None:
        raise NotImplementedError

    def run_meta(self) -> RunMeta:
        raise NotImplementedError

    def _append(self, values: dict[str, Any]) -> None:
        raise NotImplementedError

    def _update(self, trial_id: int, values: dict[str, Any]) -> None:
        raise NotImplementedError

    def columns(self) -> dict[str, np.ndarray]:
        """Column name -> array of n_trials rows (params columns are (n_trials, n_params))."""
        raise NotImplementedError

    def flush(self) -> None:
        """Make everything written so far durable."""

    def close(self) -> None:
        """Flush and release the store."""

    # --- helpers ----------------------------------------------------------------------------------
    def _writable(self) -> None:
        if self.read_only:
            raise StorageError("storage is open read-only", expected="a writable store")

    def n_trials(self) -> int:
        return len(self.columns()["trial_id"])

    def add_trial(self, trial_id: int, params_unit: np.ndarray, params: np.ndarray, phase: str,
                  parent: int, seed: int) -> None:
        """Record a sampled trial (status waiting); `trial_id` must be the next id."""
        self._writable()
        n = self.n_trials()
        if trial_id != n:
            raise StorageError("trial ids must be added densely", received=trial_id, expected=n)
        self._append({"trial_id": trial_id, "params_unit": params_unit, "params": params,
                      "phase": phase.encode(), "parent": parent, "seed": seed, "status": b"waiting"})

    def finish_trial(self, trial_id: int, result: TrialResult, objective: float,
                     finished_at_unix_s: float | None = None) -> bool:
        """Store a result once: False (and nothing written) if the trial is already finished."""
        self._writable()
        if not 0 <= trial_id < self.n_trials():
            raise StorageError("no such trial", received=trial_id, expected=f"0 <= id < {self.n_trials()}")
        if self.columns()["status"][trial_id] != b"waiting":
            return False
        status = b"complete" if result.status == TrialStatus.COMPLETE else b"failed"
        self._update(trial_id, {
            "status": status, "reason": result.reason.encode("utf-8", "replace")[:160],
            "objective": objective if math.isfinite(objective) else np.nan,
            "distance_m": result.distance_m, "ntrt_distance_cm": result.ntrt_distance_cm,
            "speed_cm_s": result.speed_cm_s, "work_j": result.work_j, "cot": result.cot,
            "mass_kg": result.mass_kg, "sim_time_s": result.sim_time_s, "wall_time_s": result.wall_time_s,
            "worker_id": result.worker_id.encode("utf-8", "replace")[:64],
            "finished_at_unix_s": time.time() if finished_at_unix_s is None else finished_at_unix_s})
        return True

    def set_verification(self, trial_id: int, verdict: str, distance_m: float = math.nan, reason: str = "") -> None:
        """Record the re-simulation verdict of a trial (pending, holds, not_reproduced)."""
        self._writable()
        if not 0 <= trial_id < self.n_trials():
            raise StorageError("no such trial", received=trial_id, expected=f"0 <= id < {self.n_trials()}")
        if verdict not in ("pending", "holds", "not_reproduced"):
            raise StorageError("unknown verification verdict", received=verdict,
                               expected="pending, holds or not_reproduced")
        self._update(trial_id, {"verification": verdict.encode(), "verify_distance_m": distance_m,
                                "verify_reason": reason.encode("utf-8", "replace")[:160]})

    def trial(self, trial_id: int) -> TrialRecord:
        cols = self.columns()
        n = len(cols["trial_id"])
        if not 0 <= trial_id < n:
            raise StorageError("no such trial", received=trial_id, expected=f"0 <= id < {n}")
        return TrialRecord.from_columns(cols, trial_id)

    def counts(self) -> dict[str, int]:
        status = self.columns()["status"]
        return {s: int(np.count_nonzero(status == s.encode())) for s in ("waiting", "complete", "failed")}

    def best_ids(self, k: int) -> list[int]:
        """Ids of the k complete trials with the highest objective, best first (ties: lower id)."""
        cols = self.columns()
        obj = cols["objective"]
        # a result a finer re-simulation did not reproduce never counts as best
        valid = (cols["status"] == b"complete") & (cols["verification"] != b"not_reproduced")
        score = np.where(valid & np.isfinite(obj), obj, -np.inf)
        k = min(k, int(np.count_nonzero(np.isfinite(score))))
        if k <= 0:
            return []
        top = np.argpartition(-score, k - 1)[:k] if k < score.size else np.arange(score.size)
        # Ties at the cut are broken by the lowest id, so proposals are reproducible.
        cut = score[top].min()
        top = np.union1d(top, np.flatnonzero(score == cut))
        order = np.lexsort((top, -score[top]))
        return [int(i) for i in top[order[:k]]]

    def best(self, k: int) -> list[TrialRecord]:
        cols = self.columns()
        return [TrialRecord.from_columns(cols, i) for i in self.best_ids(k)]

    def waiting_ids(self) -> list[int]:
        return [int(i) for i in np.flatnonzero(self.columns()["status"] == b"waiting")]

    def __enter__(self) -> BaseStorage:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
