"""What the per-trial wall-clock limit costs: a trial run in the worker's trial process (worker.service.sandbox)
against the same trial called in-process, and how long a hung trial holds a worker.

Prints one JSON object: per-trial overhead of the pipe round trip on the test objective (microseconds,
median of --repeats batches), the same on short physics trials (tetraspine-ntrt, Bullet), the start of
a fresh trial process (after a timeout), and the time from a hang to the worker's next result.
usage: python bench/trial_limit.py [--trials 500] [--physics 20] [--repeats 5]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from spinefarm.coordinator.problem import build_run_config  # noqa: E402
from spinefarm.protocol.work import TrialAssignment  # noqa: E402
from spinefarm.worker.service.evaluators import build_evaluator  # noqa: E402
from spinefarm.worker.service.sandbox import TrialLimit, TrialSandbox  # noqa: E402


def assignments(n_params: int, n: int) -> list[TrialAssignment]:
    return [TrialAssignment(i, 1, tuple(((i * 0.37 + j * 0.11) % 0.7) + 0.3 for j in range(n_params)), i, 60.0, None)
            for i in range(n)]


def per_trial_s(run, batch: list[TrialAssignment]) -> float:
    t0 = time.perf_counter()
    for a in batch:
        run(a)
    return (time.perf_counter() - t0) / len(batch)


def overhead(config, n: int, repeats: int) -> dict:
    batch = assignments(len(config.space()), n)
    direct = build_evaluator(config)
    box = TrialSandbox(config, TrialLimit(min_s=60.0))
    try:
        direct(batch[0]), box.run(batch[0])  # warm: set-up caches, compiled kernels
        inproc = [per_trial_s(direct, batch) for _ in range(repeats)]
        boxed = [per_trial_s(box.run, batch) for _ in range(repeats)]
    finally:
        box.close()
    return {"trials_per_batch": n, "repeats": repeats, "in_process_ms": round(1e3 * statistics.median(inproc), 4),
            "in_trial_process_ms": round(1e3 * statistics.median(boxed), 4),
            "overhead_us": round(1e6 * (statistics.median(boxed) - statistics.median(inproc)), 1),
            "overhead_spread_us": [round(1e6 * (b - i), 1) for b, i in zip(sorted(boxed), sorted(inproc), strict=True)]}


def hang_cost(repeats: int) -> dict:
    cfg = build_run_config("hang", "sphere:2", duration_s=0.01)
    cfg = replace(cfg, trial_config={"duration_s": 0.01, "poison": {"hang": [0.0, 0.5]}})
    box = TrialSandbox(cfg, TrialLimit(min_s=0.5))
    try:
        box.run(TrialAssignment(0, 1, (0.9, 0.5), 1, 60.0, None))
        starts, hangs = [], []
        for _ in range(repeats):
            t0 = time.perf_counter()
            r = box.run(TrialAssignment(0, 1, (0.1, 0.5), 1, 60.0, None))
            hangs.append(time.perf_counter() - t0)
            assert r is not None and r.reason.startswith("timeout:"), r
            t0 = time.perf_counter()
            box.run(TrialAssignment(0, 1, (0.9, 0.5), 1, 60.0, None))
            starts.append(time.perf_counter() - t0)
    finally:
        box.close()
    return {"limit_s": 0.5, "hang_to_timeout_s": round(statistics.median(hangs), 3),
            "next_trial_after_timeout_s": round(statistics.median(starts), 3),
            "spread_s": [round(min(starts), 3), round(max(starts), 3)]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=500)
    ap.add_argument("--physics", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    out = {"sphere": overhead(build_run_config("s", "sphere:8"), args.trials, args.repeats)}
    if args.physics:
        out["physics_tetraspine_ntrt_1s"] = overhead(build_run_config("p", "tetraspine-ntrt", duration_s=1.0),
                                                     args.physics, max(1, args.repeats // 2))
    out["hang"] = hang_cost(3)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
