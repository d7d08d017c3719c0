"""How the API reads rows of a large run file: one read per column for a set of trials (Hdf5Reader.records, what
/runs/{id}/trials, /best and /pareto use) against a row at a time (Hdf5Reader.trial per id), side by side.

    python bench/api_reads.py [--trials 20000] [--page 1000] [--repeats 3]

Writes the run file with a real search of the test objective (`spinefarm search sphere:3`), then times, for a
page of `--page` trials in the middle of the run, for the Pareto front, and for every complete trial, both ways
(the best of `--repeats`). Prints one JSON object; `ratio` is row-at-a-time over by-column.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from spinefarm.storage.hdf5_reader import Hdf5Reader  # noqa: E402


def best_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=20000)
    ap.add_argument("--page", type=int, default=1000)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        run = Path(tmp) / "run.h5"
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "spinefarm", "search", "sphere:3", "--trials", str(args.trials),
                        "--workers", "2", "--sampler", "random", "--out", str(run), "--api-port", "-1", "--quiet"],
                       cwd=ROOT, check=True, capture_output=True)
        search_s = time.perf_counter() - t0
        with Hdf5Reader(run) as reader:
            n = reader.n_trials()
            start = max(0, n // 2 - args.page // 2)
            sets = {"page": list(range(start, min(n, start + args.page))), "pareto_front": reader.pareto_ids(),
                    "best_1000": reader.best_ids(1000)}
            rows = {}
            for name, ids in sets.items():
                by_row = best_time(lambda ids=ids: [reader.trial(i) for i in ids], args.repeats)
                by_column = best_time(lambda ids=ids: reader.records(ids), args.repeats)
                assert [reader.trial(i) for i in ids[:50]] == reader.records(ids[:50])
                rows[name] = {"trials": len(ids), "row_at_a_time_s": by_row, "by_column_s": by_column,
                              "ratio": by_row / by_column if by_column else None}
    print(json.dumps({"benchmark": "api_reads", "trials_in_run": n, "search_s": search_s, "reads": rows}))


if __name__ == "__main__":
    main()
