"""How many trials per second one coordinator sustains end to end, and physics scaling 1 vs 2 workers.

Real transport and storage: an in-process coordinator (Zenoh router on loopback, HDF5 file with SWMR)
and `spinefarm worker` processes on the built-in test objective "sphere" (microseconds per trial), so
the coordinator, not the objective, is what is measured. The rate counts only the steady state:
from the moment every worker has asked for work until the budget is met.

The cost of durable acknowledgement: the same runs with and without the fsync that ends every flush
(a result is acknowledged only after it), one after the other, as a ratio (`fsync` in the summary).
The run files go to --dir (default: the system's temp directory), whose disk is what fsync pays for.

Prints one JSON object per measurement; the last line is one JSON object with everything.
usage: python bench/coordinator_throughput.py [--workers 2 8 32] [--batch 1 16 0] [--trials 20000]
       [--physics-trials 8 --physics-duration 1.0 | --no-physics] [--fsync-workers 2 8] [--fsync-batch 1 0]
       [--dir DIR] [--no-resume]
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from spinefarm.cli.service_commands import free_port  # noqa: E402
from spinefarm.coordinator.problem import build_run_config  # noqa: E402
from spinefarm.coordinator.service import CoordinatorService  # noqa: E402
from spinefarm.coordinator.setup import SearchSettings, new_run  # noqa: E402
from spinefarm.protocol.envelope import decode_message, encode_message  # noqa: E402
from spinefarm.protocol.errors import MessageError  # noqa: E402
from spinefarm.protocol.work import WorkGrant, WorkRequest  # noqa: E402


def spawn_workers(endpoint: str, run_id: str, n: int, batch: int) -> list[subprocess.Popen]:
    batch_args = ["--batch", str(batch)] if batch > 0 else []  # 0: the worker sizes its batches itself
    return [subprocess.Popen([sys.executable, "-m", "spinefarm", "worker", "--connect", endpoint, "--run", run_id,
                              *batch_args, "--exit-when-done", "--worker-id", f"bench-{i}"],
                             cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) for i in range(n)]


class StartGate:
    """Holds every worker at an empty grant until all N have asked, so the clock starts with all of them.

    Without it, on 2 cores the first workers finish a whole budget before the 32nd process has started.
    """

    def __init__(self, core, n_workers: int) -> None:
        self.core, self.n, self.seen = core, n_workers, set()
        self.inner = core.handle_work
        self.t0: float | None = None

    def handle_work(self, payload: bytes) -> bytes:
        if self.t0 is None:
            try:
                self.seen.add(decode_message(payload, WorkRequest).worker_id)
            except MessageError:
                return self.inner(payload)
            if len(self.seen) < self.n:
                return encode_message(WorkGrant(self.core.run_id, self.core.config_hash, (), 0.02, False))
            self.t0 = time.monotonic()
        return self.inner(payload)


_RUN_NUMBER = itertools.count()


def measure(morphology: str, n_workers: int, batch: int, trials: int, duration_s: float | None,
            tmp: Path, fsync: bool = True) -> dict:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    # one file per measurement: the fsync comparison repeats a setting the main sweep measured already
    run_id = f"bench-{morphology.replace(':', '')}-{n_workers}-{batch}-{int(fsync)}-{os.getpid()}-{next(_RUN_NUMBER)}"
    config = build_run_config(run_id, morphology, duration_s=duration_s)
    core, storage = new_run(config, SearchSettings(trials=trials, lease_s=600.0), tmp / f"{run_id}.h5")
    storage.fsync = fsync
    gate = StartGate(core, n_workers)
    core.handle_work = gate.handle_work
    service = CoordinatorService(core, storage, listen=[endpoint]).start()
    t_spawn = time.monotonic()
    procs = spawn_workers(endpoint, run_id, n_workers, batch)
    try:
        service.wait_done(timeout_s=3600)
        t1 = time.monotonic()
        counts = storage.counts()
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            p.wait(30)
        service.close()
    t0 = gate.t0 if gate.t0 is not None else t1
    rate = trials / (t1 - t0) if t1 > t0 else float("nan")
    return {"morphology": morphology, "workers": n_workers, "batch": batch, "fsync": fsync, "trials": trials,
            "duration_s": duration_s, "measured_wall_s": round(t1 - t0, 3), "trials_per_s": round(rate, 1),
            "complete": counts["complete"], "failed": counts["failed"], "startup_s": round(t0 - t_spawn, 2)}


def fsync_cost(workers: list[int], batches: list[int], trials: int, tmp: Path) -> list[dict]:
    """Trials per second with and without fsync before acknowledging, measured back to back."""
    out = []
    for batch in batches:
        for n in workers:
            without = measure("sphere:8", n, batch, trials, None, tmp, fsync=False)
            with_ = measure("sphere:8", n, batch, trials, None, tmp, fsync=True)
            r = {"workers": n, "batch": batch, "trials": trials,
                 "without_fsync_trials_per_s": without["trials_per_s"],
                 "with_fsync_trials_per_s": with_["trials_per_s"],
                 "ratio": round(with_["trials_per_s"] / without["trials_per_s"], 3)}
            print(json.dumps({"fsync_cost": r}), flush=True)
            out.append(r)
    return out


def resume_cost(tmp: Path, rows: int) -> dict:
    """Time to reopen a killed SWMR writer's file for writing (read via SWMR, rewrite, replace)."""
    import numpy as np

    from spinefarm.protocol.results import TrialResult
    from spinefarm.protocol.states import TrialStatus
    from spinefarm.storage.hdf5 import Hdf5Storage

    config = build_run_config("resume-bench", "sphere:116")
    _, s = new_run(config, SearchSettings(trials=rows), tmp / "resume.h5")
    u = np.full(116, 0.5)
    for i in range(rows):
        s.add_trial(i, u, u, "monte_carlo", -1, i)
        s.finish_trial(i, TrialResult(TrialStatus.COMPLETE, "", 1.0, 1, 1, 1, 1, 1, 1, 1, i, trial_id=i), 1.0)
    s.flush()  # left open in SWMR mode, as after a kill -9
    s._lock.release()  # the kernel releases a killed writer's run lock; this writer is in the same process
    t = time.perf_counter()
    r = Hdf5Storage.resume(tmp / "resume.h5")
    dt = time.perf_counter() - t
    r.close()
    s._file = None  # the "killed" writer's handle: never closed cleanly
    return {"resume_rows": rows, "resume_params": 116, "resume_s": round(dt, 3),
            "file_mb": round((tmp / "resume.h5").stat().st_size / 1e6, 1)}


def _filesystem(path: str) -> str:
    """Type and device of the file system holding `path` (fsync on tmpfs costs nothing)."""
    r = subprocess.run(["df", "--output=fstype,source", path], capture_output=True, text=True)
    return " ".join(r.stdout.split()[2:]) if r.returncode == 0 else "unknown"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, nargs="*", default=[2, 8, 32], help="none: physics only")
    ap.add_argument("--batch", type=int, nargs="+", default=[1, 16, 0], help="0: auto")
    ap.add_argument("--trials", type=int, default=20000)
    ap.add_argument("--physics-trials", type=int, default=16)
    ap.add_argument("--physics-duration", type=float, default=1.0)
    ap.add_argument("--no-physics", action="store_true")
    ap.add_argument("--fsync-workers", type=int, nargs="*", default=[2, 8], help="none: no fsync comparison")
    ap.add_argument("--fsync-batch", type=int, nargs="+", default=[1, 0], help="0: auto")
    ap.add_argument("--dir", default=None, help="where the run files go (its disk is what fsync costs)")
    ap.add_argument("--no-resume", action="store_true")
    args = ap.parse_args()
    out: dict = {"cpus": os.cpu_count(), "sphere": [], "physics": None, "fsync": []}
    with tempfile.TemporaryDirectory(dir=args.dir) as d:
        out["dir_filesystem"] = _filesystem(d)
        tmp = Path(d)
        for batch in args.batch:
            for n in args.workers:
                r = measure("sphere:8", n, batch, args.trials, None, tmp)
                print(json.dumps(r), flush=True)
                out["sphere"].append(r)
        if not args.no_physics:
            one = measure("tetraspine", 1, 1, args.physics_trials, args.physics_duration, tmp)
            print(json.dumps(one), flush=True)
            two = measure("tetraspine", 2, 1, args.physics_trials, args.physics_duration, tmp)
            print(json.dumps(two), flush=True)
            out["physics"] = {"one_worker": one, "two_workers": two,
                              "speedup": round(two["trials_per_s"] / one["trials_per_s"], 3),
                              "efficiency": round(two["trials_per_s"] / (2 * one["trials_per_s"]), 3)}
        out["fsync"] = fsync_cost(args.fsync_workers, args.fsync_batch, args.trials, tmp)
        if not args.no_resume:
            out["resume"] = resume_cost(tmp, 20000)
            print(json.dumps(out["resume"]), flush=True)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
