"""The evaluations table: every judge, audit, referee and opinion run of a parameter set, one row each.

The trials table holds the search's own rows (each screen rung, each promotion) and, on a judged or audited
row, the verdict that sums them up (verification, audit columns, which rank and filter the best). This table
keeps each such run as it happened: which row it checked (`trial_id`, the link to the parameter set), its
kind (protocol.states.EvaluationKind), the fidelity it ran at, what it measured (its distance and cost of
transport) and how long it took. Rows are appended, never changed; the
writer writes `status` last. A file of an older schema (storage.schema.OLDER_SCHEMA_VERSIONS) has no
/evaluations group: it reads as an empty table, and its runs are only the verdict columns; a file of schema 8
has no `cot` column: its rows read NaN there, and the judge's COT is "not measured".
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from spinefarm.protocol.columns import column_group
from spinefarm.protocol.errors import StorageError
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.states import EvaluationKind
from spinefarm.storage import side_table

EVALUATION_COLUMNS = column_group("evaluation")
NAMES = tuple(c.name for c in EVALUATION_COLUMNS)
GROUP = "evaluations"
# a judged best's COT in a file from before the column (schema 8)
NOT_MEASURED = "not measured (a run file from before the judge's COT was stored)"


def empty_columns(n: int = 0) -> dict[str, np.ndarray]:
    return side_table.empty_columns(EVALUATION_COLUMNS, n)


def row_of(trial_id: int, kind: str | EvaluationKind, r: TrialResult, engine: str, dt_s: float | None,
           worker_id: str = "") -> dict[str, Any]:
    """The stored values of one run of `kind` on row `trial_id` (its result `r`, from `worker_id` or the one the
    result names); a kind not of EvaluationKind is refused."""
    values = {"trial_id": trial_id, "kind": EvaluationKind.of(kind).value, "engine": engine,
              "dt_s": math.nan if dt_s is None else dt_s,
              "reason": "" if r.ok else r.reason, "distance_m": r.distance_m, "cot": r.cot,
              "perturbed_distance_m": float(r.extras.get("perturbed_distance_m", math.nan)),
              "wall_time_s": r.wall_time_s, "worker_id": worker_id or r.worker_id or "",
              "finished_at_unix_s": time.time(), "status": str(r.status)}
    return {c.name: _stored(values[c.name], c.dtype) for c in EVALUATION_COLUMNS}


def _stored(v: Any, dtype: str) -> Any:
    return v.encode("utf-8", "replace")[: int(dtype[1:])] if dtype[0] == "S" else v


class EvaluationTable:
    """Growable evaluation columns; rows [n_written, n) are not in the file yet."""

    def __init__(self, capacity: int = 64) -> None:
        self.n = self.n_written = 0
        self._cols = empty_columns(capacity)

    def append(self, row: dict[str, Any]) -> None:
        EvaluationKind.of(row["kind"])   # refused before anything is stored
        cap = len(self._cols["trial_id"])
        if self.n == cap:
            grown = empty_columns(2 * cap)
            for name, arr in self._cols.items():
                grown[name][: self.n] = arr
            self._cols = grown
        for name, v in row.items():
            self._cols[name][self.n] = v
        self.n += 1

    def columns(self) -> dict[str, np.ndarray]:
        return {name: arr[: self.n] for name, arr in self._cols.items()}

    def load(self, cols: dict[str, np.ndarray]) -> None:
        n = len(cols["trial_id"])
        self._cols = empty_columns(max(64, n))
        for name in NAMES:
            self._cols[name][:n] = cols[name]
        self.n = self.n_written = n


def check_kinds(cols: dict[str, np.ndarray], path: Any) -> None:
    """Refuse to resume from a table holding a kind not of EvaluationKind (a damaged or foreign file): one line
    naming the first such row, its kind and the known kinds."""
    bad = np.flatnonzero(~np.isin(cols["kind"], [k.stored for k in EvaluationKind]))
    if bad.size:
        raise StorageError(f"cannot resume {path}: evaluation row {int(bad[0])} of {len(cols['kind'])} has an "
                           "unknown kind", received=bytes(cols["kind"][bad[0]]),
                           expected="one of " + ", ".join(k.value for k in EvaluationKind))


def judge_wall_s(cols: dict[str, np.ndarray]) -> float:
    """The time the judge's runs and the opinions took, from the stored rows (its share of the workers' time on
    resume)."""
    wall = cols["wall_time_s"][np.isin(cols["kind"], (EvaluationKind.JUDGE.stored, EvaluationKind.OPINION.stored))]
    return float(np.sum(wall, where=np.isfinite(wall)))


def latest(cols: dict[str, np.ndarray], trial_id: int, kind: EvaluationKind) -> int | None:
    """The last stored row of `kind` on trial row `trial_id`, a complete one first."""
    rows = np.flatnonzero((cols["trial_id"] == trial_id) & (cols["kind"] == kind.stored))
    if not rows.size:
        return None
    complete = rows[cols["status"][rows] == b"complete"]
    return int((complete if complete.size else rows)[-1])


def judged_cot(cols: dict[str, np.ndarray], trial_id: int) -> tuple[float | None, str | None]:
    """(the cost of transport the judge measured on row `trial_id`, None), or (None, why there is none): its
    judge's run has no row, failed, or was stored before the column (NOT_MEASURED)."""
    i = latest(cols, trial_id, EvaluationKind.JUDGE)
    if i is None:
        return None, "not measured (no judge's run stored)"
    if cols["status"][i] != b"complete":
        return None, "not measured (the judge's run failed)"
    cot = float(cols["cot"][i])
    if math.isnan(cot):
        return None, NOT_MEASURED
    if math.isinf(cot):   # work over no distance
        return None, "infinite (the judge's run did not move)"
    return cot, None


# --- HDF5 ------------------------------------------------------------------------------------------
def create_datasets(f: Any, cols: dict[str, np.ndarray], compression: dict[str, Any]) -> None:
    side_table.create_group(f, GROUP, EVALUATION_COLUMNS, cols, compression, chunk_rows=256)


def read_datasets(f: Any) -> dict[str, np.ndarray]:
    """Every fully written row (none for a file of an older schema)."""
    return side_table.read_group(f, GROUP, EVALUATION_COLUMNS)


def write_new(f: Any, table: EvaluationTable) -> None:
    """Append the rows not yet in the file (status last, so a half-written row is never read)."""
    if table.n == table.n_written:
        return
    side_table.append_rows(f, GROUP, table.columns(), table.n_written, table.n)
    table.n_written = table.n
