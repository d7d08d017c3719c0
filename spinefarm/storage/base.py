"""BaseStorage: the primitives a results store implements, and helpers built only on them."""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from spinefarm.protocol.columns import RECORDED_EXTRAS, SCORE_NAMES
from spinefarm.protocol.errors import StorageError
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.states import REFUTED_VERDICTS, STORED_STATUSES, AuditState, TrialStatus, Verification
from spinefarm.storage import pareto
from spinefarm.storage.ranking import COT_OBJECTIVES, agreeing, judge_cots, ranked_values, screen_bias
from spinefarm.storage.schema import FILE_SCHEMA_VERSION, RunMeta, TrialRecord

# A result whose audit found it wrong, or is still refereeing it, or whose worker was quarantined (until
# another identity reproduces it), never counts as best.
DISQUALIFYING_AUDITS = (AuditState.DISAGREES.stored, AuditState.DISPUTED.stored,
                        AuditState.QUARANTINED.stored)


_RANKED_BY = ("objective", "verification", "verify_distance_m", "distance_m")   # what ranked_values reads


class BaseStorage:
    """One run's metadata and trial table.

    Call order: `create_run` once for a new run (or open an existing one), then `add_trial` when the
    sampler proposes trial n (ids are dense, 0, 1, 2, ...), `finish_trial` when its result arrives,
    `flush` at a bounded interval (what was flushed survives a crash), `close` at the end.
    Readers use `columns`, `run_meta` and the helpers; a read-only storage refuses writes.
    """

    read_only = False
    file_schema_version = FILE_SCHEMA_VERSION   # what the run file was written at (older ones still open)
    audit_writes = 0   # set_audit calls since this storage was opened (a cheap "did any audit change" for the study)

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
                  parent: int, seed: int, rung: int = 0, duration_s: float = math.nan) -> None:
        """Record a sampled trial (status waiting); `trial_id` must be the next id."""
        self._writable()
        n = self.n_trials()
        if trial_id != n:
            raise StorageError("trial ids must be added densely", received=trial_id, expected=n)
        self._append({"trial_id": trial_id, "params_unit": params_unit, "params": params,
                      "phase": phase.encode(), "parent": parent, "seed": seed,
                      "status": TrialStatus.WAITING.stored, "rung": rung, "duration_s": duration_s})

    def finish_trial(self, trial_id: int, result: TrialResult, objective: float,
                     finished_at_unix_s: float | None = None) -> bool:
        """Store a result once: False (and nothing written) if the trial is already finished."""
        self._writable()
        if not 0 <= trial_id < self.n_trials():
            raise StorageError("no such trial", received=trial_id, expected=f"0 <= id < {self.n_trials()}")
        if self.columns()["status"][trial_id] != TrialStatus.WAITING.stored:
            return False
        status = (TrialStatus.COMPLETE if result.status == TrialStatus.COMPLETE else TrialStatus.FAILED).stored
        self._update(trial_id, {**_extras_values(result.extras),
            "status": status, "reason": result.reason.encode("utf-8", "replace")[:160],
            "objective": objective if math.isfinite(objective) else np.nan,
            **{name: getattr(result, name) for name in SCORE_NAMES},
            "worker_id": result.worker_id.encode("utf-8", "replace")[:64],
            "finished_at_unix_s": time.time() if finished_at_unix_s is None else finished_at_unix_s})
        if result.episodes:
            self._add_episodes(trial_id, result.episodes)
        self._update_front(trial_id)
        return True

    def add_evaluation(self, row: dict[str, Any]) -> None:
        """Append one judge, audit or referee run (storage.evaluations.row_of)."""
        raise StorageError("this storage keeps no evaluations", expected="a storage with an evaluations table")

    def evaluations(self) -> dict[str, np.ndarray]:
        """Every judge, audit and referee run (storage.evaluations), in the order they were stored."""
        from spinefarm.storage.evaluations import empty_columns
        return empty_columns()

    def _add_episodes(self, trial_id: int, episodes: tuple) -> None:
        raise StorageError("this storage keeps no episodes", expected="a storage with an episodes table")

    def episodes(self, trial_id: int | None = None) -> dict[str, np.ndarray]:
        """The episodes table (storage.episodes) of a robust run, or of one trial in episode order; empty
        columns for a plain run."""
        from spinefarm.storage.episodes import empty_columns

        return empty_columns()

    def _update_front(self, trial_id: int) -> None:
        cols = self.columns()
        speed, cot = cols["speed_cm_s"], cols["cot"]
        if not pareto.candidates(cols["status"][trial_id : trial_id + 1], speed[trial_id : trial_id + 1],
                                 cot[trial_id : trial_id + 1])[0]:
            return
        joins, off = pareto.join_front(np.flatnonzero(cols["pareto_front"] == 1), speed, cot, trial_id)
        if joins:
            self._update(trial_id, {"pareto_front": 1})
            for i in off:
                self._update(int(i), {"pareto_front": 0})

    def pareto_ids(self) -> list[int]:
        """Ids of the trials on the Pareto front of speed (max) and COT (min), fastest first."""
        cols = self.columns()
        ids = np.flatnonzero(cols["pareto_front"] == 1)
        return [int(i) for i in ids[np.lexsort((ids, -cols["speed_cm_s"][ids]))]]

    def set_verification(self, trial_id: int, verdict: Verification | str, distance_m: float = math.nan,
                         reason: str = "", ratio: float = math.nan) -> None:
        """Record the judge's verdict of a trial (pending, holds, moved, judged, diverged; not_checked when a
        queued check is dropped) with the judge's distance and the screen-to-judge ratio."""
        self._writable()
        self._check_id(trial_id)
        allowed = tuple(Verification)
        if verdict not in allowed:
            raise StorageError("unknown verification verdict", received=verdict, expected=[str(v) for v in allowed])
        self._update(trial_id, {"verification": Verification(verdict).stored, "verify_distance_m": distance_m,
                                "verify_reason": reason.encode("utf-8", "replace")[:160], "judge_ratio": ratio})

    def set_audit(self, trial_id: int, state: AuditState | str, distance_m: float = math.nan,
                  worker_id: str = "") -> None:
        """Record the audit of a result by another worker (pending, agrees, disagrees)."""
        self._writable()
        self._check_id(trial_id)
        if state not in tuple(AuditState):
            raise StorageError("unknown audit state", received=state, expected=[str(a) for a in AuditState])
        self.audit_writes += 1
        self._update(trial_id, {"audit": AuditState(state).stored, "audit_distance_m": distance_m,
                                "audit_worker_id": worker_id.encode("utf-8", "replace")[:64]})

    def _check_id(self, trial_id: int) -> None:
        if not 0 <= trial_id < self.n_trials():
            raise StorageError("no such trial", received=trial_id, expected=f"0 <= id < {self.n_trials()}")

    def trial(self, trial_id: int) -> TrialRecord:
        cols = self.columns()
        n = len(cols["trial_id"])
        if not 0 <= trial_id < n:
            raise StorageError("no such trial", received=trial_id, expected=f"0 <= id < {n}")
        return TrialRecord.from_columns(cols, trial_id)

    def counts(self) -> dict[str, int]:
        status = self.columns()["status"]
        return {s.value: int(np.count_nonzero(status == s.stored)) for s in STORED_STATUSES}

    def audit_counts(self) -> dict[str, int]:
        """How the audits came out: audits_pending, audits_agrees, audits_disagrees."""
        audit = self.columns()["audit"]
        return {f"audits_{a.value}": int(np.count_nonzero(audit == a.stored)) for a in AuditState
                if a != AuditState.NOT_AUDITED}

    def best_ids(self, k: int) -> list[int]:
        """Ids of the k complete trials with the highest ranked value (storage.ranking: the judged figure of
        a judged set), best first (ties: lower id). In a multi-fidelity run a trial of a higher rung (a longer
        trial) ranks before any of a lower one."""
        return self._ranked_ids(k, agreed_only=False)

    def _ranked_ids(self, k: int, agreed_only: bool) -> list[int]:
        cols = self.columns()
        # agreed_only: the few rows another identity's audit agreed with, the only ones looked at further
        ids = np.flatnonzero(agreeing(cols["audit"])) if agreed_only else slice(None)
        # a set whose judge run diverged never counts as best
        valid = (cols["status"][ids] == TrialStatus.COMPLETE.stored) & np.isfinite(cols["objective"][ids]) & \
            ~np.isin(cols["verification"][ids], REFUTED_VERDICTS) & \
            ~np.isin(cols["audit"][ids], DISQUALIFYING_AUDITS)  # nor one other workers did not reproduce (or dispute)
        ids = ids[valid] if agreed_only else np.flatnonzero(valid)
        if k <= 0 or ids.size == 0:
            return []
        objective = self.run_meta().objective
        ranked = {c: cols[c][ids] for c in _RANKED_BY}
        if objective in COT_OBJECTIVES:  # a judged set ranks by the judge's COT too
            ranked |= {"cot": cols["cot"][ids], "judge_cot": judge_cots(self.evaluations(), ids)}
        value = ranked_values(ranked, objective, screen_bias(cols))   # the bias from every row, not these
        order = np.lexsort((ids, -value, -cols["rung"][ids]))
        return [int(i) for i in ids[order[:k]]]

    def reported_best_ids(self, k: int) -> tuple[list[int], int | None]:
        """(the k best sets the run reports, best first; the better set still pending its audit, or None).
        With auditing on a set is reported best only once another identity's audit agreed with it
        (storage.ranking); the best-ranked set whose audit has not agreed yet is the pending one. Without
        auditing these are best_ids(k) and None."""
        if not self.run_meta().settings.audit.enabled:
            return self.best_ids(k), None
        top = self.best_ids(1)
        pending = top[0] if top and not agreeing(self.columns()["audit"][top[0]: top[0] + 1])[0] else None
        return self._ranked_ids(k, agreed_only=True), pending

    def reported_best(self, k: int) -> tuple[list[TrialRecord], TrialRecord | None]:
        """reported_best_ids as records."""
        ids, pending = self.reported_best_ids(k)
        return self.records(ids), None if pending is None else self.trial(pending)

    def records(self, ids: list[int]) -> list[TrialRecord]:
        """The trials `ids`, in that order."""
        cols = self.columns()
        return [TrialRecord.from_columns(cols, i) for i in ids]

    def best(self, k: int) -> list[TrialRecord]:
        return self.records(self.best_ids(k))

    def count_rung(self, rung: int) -> int:
        return int(np.count_nonzero(self.columns()["rung"] == rung))

    def waiting_ids(self) -> list[int]:
        return [int(i) for i in np.flatnonzero(self.columns()["status"] == TrialStatus.WAITING.stored)]

    def __enter__(self) -> BaseStorage:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _extras_values(extras: dict) -> dict:
    """The recorded extras of a result as column values (missing ones stay empty)."""
    out: dict = {}
    for part in RECORDED_EXTRAS:
        if part.name not in extras:
            continue
        value = extras[part.name]
        if part.dtype.startswith("S"):
            out[part.name] = str(value).encode("utf-8", "replace")[: int(part.dtype[1:])]
        elif isinstance(value, int | float) and not isinstance(value, bool):
            out[part.name] = float(value)
    return out
