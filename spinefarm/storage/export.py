"""Quick looks at a run: every trial as CSV, the best trials as a text table."""

from __future__ import annotations

import csv
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TextIO

from spinefarm.storage.base import BaseStorage
from spinefarm.storage.ranking import counted_distance_m
from spinefarm.storage.schema import COLUMNS, VECTOR_COLUMNS


def write_csv(storage: BaseStorage, out: TextIO, ids: Sequence[int] | None = None) -> None:
    """One row per trial (or per trial in `ids`); parameters as physical values in columns named after them."""
    names = list(storage.run_meta().param_names)
    cols = storage.columns()
    scalar = [c.name for c in COLUMNS if c.name not in VECTOR_COLUMNS]
    w = csv.writer(out)
    w.writerow(scalar + names)
    for i in range(len(cols["trial_id"])) if ids is None else ids:
        row = [cols[n][i].decode("utf-8", "replace") if isinstance(cols[n][i], bytes) else cols[n][i].item()
               for n in scalar]
        w.writerow(row + cols["params"][i].tolist())


def best_table(storage: BaseStorage, k: int) -> str:
    """The k best sets as the run ranks them: by the distance that counts (the judge's on a judged set, shown as
    counted_m beside its verdict), so a judged set may rank above a set whose screened objective is higher."""
    meta = storage.run_meta()
    lines = [f"{'rank':>4} {'trial':>6} {'phase':<11} {'objective':>10} {'distance_m':>10} {'counted_m':>10} "
             f"{'verdict':<12} {'speed_cm_s':>10} {'work_j':>9} {'cot':>8}"]
    best = storage.reported_best(k)[0]   # with auditing on, only sets another identity's audit agreed with
    for rank, r in enumerate(best, 1):
        counted = counted_distance_m(r.verification, r.distance_m, r.verify_distance_m)
        lines.append(f"{rank:>4} {r.trial_id:>6} {r.phase:<11} {r.objective:>10.4g} {r.distance_m:>10.4g} "
                     f"{counted:>10.4g} {r.verification or '-':<12} {r.speed_cm_s:>10.4g} {r.work_j:>9.4g} "
                     f"{r.cot:>8.4g}")
    if best:
        b = best[0]
        lines.append(f"best trial {b.trial_id} parameters:")
        lines += [f"  {n} = {v:.6g} {u}".rstrip() for n, v, u in
                  zip(meta.param_names, b.params, meta.param_units, strict=True)]
    else:
        lines.append("no complete trial")
    return "\n".join(lines)


def gait_params(storage: BaseStorage, trial_id: int | None = None) -> dict[str, Any]:
    """The best trial (or `trial_id`) as a `spinefarm trial --params` file: controller space, named
    physical values, and where it came from (run, trial, scores, trial length) for the record."""
    from spinefarm.protocol.errors import StorageError

    best = storage.reported_best(1)[0] if trial_id is None else [storage.trial(trial_id)]
    if not best or best[0].status != "complete":
        raise StorageError("no complete trial to export", received=trial_id if trial_id is not None
                           else str(storage.run_meta().run_id), expected="a complete trial")
    b, meta = best[0], storage.run_meta()
    # no controller given: the morphology's first (its default), named so the file says which space it is
    controller = meta.controller or (meta.morphology_spec.get("controllers") or [None])[0]
    return {"morphology": meta.morphology, "controller": controller,
            "params": dict(zip(meta.param_names, b.params, strict=True)),
            "source": {"run_id": meta.run_id, "trial_id": b.trial_id, "seed": b.seed,
                       "sampler": meta.sampler.get("name", meta.sampler.get("kind")),
                       "speed_cm_s": b.speed_cm_s, "cot": b.cot, "distance_m": b.distance_m,
                       "sim_time_s": b.sim_time_s, "verification": b.verification or "not_checked"}}


def write_gait(path: str | Path, gait: dict[str, Any]) -> None:
    """A gait (gait_params, or any `spinefarm trial --params` dict) as its JSON file, folders made."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text(json.dumps(gait, indent=1) + "\n")
