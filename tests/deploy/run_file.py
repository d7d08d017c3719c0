"""What a deployment's run file must show at the end: its exact budget, nothing lost, nothing twice."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from tests.deploy.host import DeployError


def check_run_file(path: Path, trials: int) -> dict[str, Any]:
    """Every row complete, `trials` new parameter sets, rows numbered 0..n-1 and each promotion made once."""
    import spinefarm

    df = spinefarm.load_run(str(path))
    fresh = df[df.phase != "promoted"]
    promoted = df[df.phase == "promoted"]
    problems = []
    if len(fresh) != trials:
        problems.append(f"{len(fresh)} parameter sets instead of the budget {trials}")
    if list(df.index) != list(range(len(df))):
        problems.append("trial ids are not 0..n-1")
    if not (df.status == "complete").all():
        bad = df[df.status != "complete"]
        problems.append(f"{len(bad)} trials not complete (first: {bad.iloc[0].status} {bad.iloc[0].reason!r})")
    if promoted.duplicated(["parent", "rung"]).any():
        problems.append("a trial was promoted twice to the same rung")
    if problems:
        raise DeployError(f"run file {path.name}: " + "; ".join(problems))
    return {"trials_stored": len(df), "parameter_sets": len(fresh), "promoted": len(promoted),
            "failed": int((df.status == "failed").sum()), "workers_seen": int(df.worker_id.nunique()),
            "best_objective": round(float(df.objective.max()), 4)}
