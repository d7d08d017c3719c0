"""The coordinator's CMA-ES with one BLAS thread (the `spinefarm` command's default) against OpenBLAS's own
choice (a thread per core), side by side.

Each run is a real local search (`spinefarm search sphere:N --sampler cmaes`: the analytic test robot, so the
sampler's proposals are the work) with one worker; the two settings alternate, `--repeats` times. With
`--busy K`, K processes spin at full load meanwhile, as the workers of a real search keep the cores busy.

    python bench/blas_threads.py                         # 200 dimensions (the tetrahedral complex has 202)
    python bench/blas_threads.py --dims 50,200 --trials 80 --repeats 3 --busy 2

Prints one JSON object: per dimension and setting the median wall time of the search and the seconds per trial,
and `threads_default_over_one` (wall time with OpenBLAS's threads over wall time with one thread).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _spin(stop) -> None:
    while not stop.is_set():
        sum(i * i for i in range(10_000))


def _search(dims: int, trials: int, threads: str | None, out: Path) -> float:
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    if threads is not None:
        env["OPENBLAS_NUM_THREADS"] = threads
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "spinefarm", "search", f"sphere:{dims}", "--sampler", "cmaes",
                    "--trials", str(trials), "--workers", "1", "--out", str(out), "--overwrite", "--api-port", "-1",
                    "--quiet", "--seed", "1"], cwd=ROOT, env=env, check=True, capture_output=True)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dims", default="200", help="comma-separated numbers of parameters")
    ap.add_argument("--trials", type=int, default=80)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--busy", type=int, default=0, help="processes spinning at full load meanwhile")
    args = ap.parse_args()
    cores = os.cpu_count() or 1
    settings = {"one_thread": None, "openblas_default": str(cores)}
    stop = mp.Event()
    spinners = [mp.Process(target=_spin, args=(stop,), daemon=True) for _ in range(args.busy)]
    for p in spinners:
        p.start()
    report: dict = {"benchmark": "blas_threads", "cores": cores, "busy": args.busy, "trials": args.trials,
                    "repeats": args.repeats, "dims": {}}
    try:
        with tempfile.TemporaryDirectory() as tmp:
            for dims in (int(d) for d in args.dims.split(",")):
                walls: dict[str, list[float]] = {name: [] for name in settings}
                for r in range(args.repeats):
                    for name, threads in settings.items():
                        walls[name].append(_search(dims, args.trials, threads, Path(tmp) / f"{name}-{r}.h5"))
                row = {name: {"wall_s": statistics.median(w), "s_per_trial": statistics.median(w) / args.trials,
                              "all_wall_s": w} for name, w in walls.items()}
                row["threads_default_over_one"] = row["openblas_default"]["wall_s"] / row["one_thread"]["wall_s"]
                report["dims"][str(dims)] = row
    finally:
        stop.set()
        for p in spinners:
            p.join(5)
    print(json.dumps(report))


if __name__ == "__main__":
    main()
