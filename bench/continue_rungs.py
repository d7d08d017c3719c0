"""Nothing simulated twice: the same search with promotions continued from their last rung's kept end and with
`--no-continue`, side by side (interleaved), as real `spinefarm search` processes (embedded Zenoh, local workers,
HDF5 run files).

    python bench/continue_rungs.py [--morphology tetraspine] [--controller sidewinding] [--engine mujoco]
        [--dt 0.002] [--engine-option segment_contacts=off] [--rungs 5,10,30] [--eta 4] [--settle 1]
        [--trials 120] [--duration 30] [--workers 2] [--seed 1] [--repeats 1] [--verify]

Per run: the simulated seconds the ladder asks for (settle included) and those the workers simulated (less each
row's `continued_s`), per parameter set sampled; the CPU seconds of the whole search (coordinator, workers, their
trial processes: getrusage of the reaped children) and the sum of the trials' own wall seconds, per parameter set;
how many promotions went on from a kept end; how many rows after its rung a promotion came (`promotion_lag_rows`).
`end_bytes`: the size of one kept end (worker.trial.continued) of the first rung, measured in this process.
Prints one JSON object; medians over repeats under "on" and "off", their ratios under "saving".
Judges are off unless --verify (a judge's cost is the same either way).
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from statistics import median

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _command(args: argparse.Namespace, out: Path, on: bool) -> list[str]:
    cmd = [sys.executable, "-m", "spinefarm", "search", args.morphology, "--engine", args.engine, "--dt", str(args.dt),
           "--rungs", args.rungs, "--eta", str(args.eta), "--settle", str(args.settle), "--trials", str(args.trials),
           "--duration", str(args.duration), "--workers", str(args.workers), "--seed", str(args.seed),
           "--out", str(out), "--api-port", "-1", "--quiet"]
    for option in args.engine_option:
        cmd += ["--engine-option", option]
    if args.controller:
        cmd += ["--controller", args.controller]
    if not args.verify:
        cmd.append("--no-verify")
    if not on:
        cmd.append("--no-continue")
    return cmd


def run_search(args: argparse.Namespace, out: Path, on: bool) -> dict:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(_command(args, out, on), cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise SystemExit(f"search ({'on' if on else 'off'}) failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
    from spinefarm.storage.hdf5_reader import read_run

    _, cols = read_run(out)
    ran = cols["status"] == b"complete"
    asked = (cols["duration_s"] + np.nan_to_num(cols["settle_s"]))[ran]
    continued = np.nan_to_num(cols["continued_s"])[ran]
    promoted = ran & (cols["phase"] == b"promoted")
    sets = int(np.count_nonzero(cols["rung"] == 0))
    cpu_s = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    lag = (cols["trial_id"] - cols["parent"])[promoted]
    return {"continue": on, "wall_s": round(wall, 2), "parameter_sets": sets, "rows": int(ran.sum()),
            "promotions": int(promoted.sum()), "continued": int(np.count_nonzero(continued > 0)),
            "sim_s_asked_per_set": round(float(asked.sum()) / sets, 3),
            "sim_s_run_per_set": round(float((asked - continued).sum()) / sets, 3),
            "cpu_s_per_set": round(cpu_s / sets, 4),
            "trial_wall_s_per_set": round(float(cols["wall_time_s"][ran].sum()) / sets, 4),
            "promotion_lag_rows": {"median": float(np.median(lag)) if len(lag) else None,
                                   "max": int(lag.max()) if len(lag) else None}}


def end_bytes(args: argparse.Namespace) -> int:
    """The pickled size of one kept end of the first rung (the engine's state, the law's, the trial's log)."""
    import dataclasses

    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.worker.trial.setup import SetupCache
    from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, simulate

    morph = load_morphology(args.morphology)
    options = dict(o.split("=", 1) for o in args.engine_option)
    cfg = TrialConfig(engine=args.engine, dt_s=args.dt, settle_s=args.settle, engine_options=options)
    cache = SetupCache()
    simulate(morph, random_unit_params(morph, 1, args.controller), dataclasses.replace(
        cfg, duration_s=float(args.rungs.split(",")[0])), 1, controller=args.controller, setup=cache, resume=True)
    ends = next(iter(cache._items.values())).rung_ends
    end = next(iter(ends._ends.values()))
    return len(pickle.dumps(end, protocol=pickle.HIGHEST_PROTOCOL))


def _medians(runs: list[dict]) -> dict:
    keys = ("wall_s", "sim_s_asked_per_set", "sim_s_run_per_set", "cpu_s_per_set", "trial_wall_s_per_set")
    out = {k: median(r[k] for r in runs) for k in keys}
    out["spread"] = {k: [min(r[k] for r in runs), max(r[k] for r in runs)] for k in keys}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--morphology", default="tetraspine")
    ap.add_argument("--controller", default="sidewinding")
    ap.add_argument("--engine", default="mujoco")
    ap.add_argument("--dt", type=float, default=0.002)
    ap.add_argument("--engine-option", action="append", default=None, metavar="KEY=VALUE",
                    help="default segment_contacts=off (the paper-size search's screen)")
    ap.add_argument("--rungs", default="5,10,30")
    ap.add_argument("--eta", type=int, default=4)
    ap.add_argument("--settle", type=float, default=1.0)
    ap.add_argument("--trials", type=int, default=120)
    ap.add_argument("--duration", type=float, default=30.0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--repeats", type=int, default=1, help="on/off pairs, interleaved (the order alternates)")
    ap.add_argument("--verify", action="store_true", help="keep the Bullet judge of new bests (default: off)")
    ap.add_argument("--keep", metavar="DIR", help="keep the run files here")
    args = ap.parse_args()
    args.engine_option = args.engine_option or ["segment_contacts=off"]
    if args.repeats < 1 or args.trials < 1:
        raise SystemExit(f"--repeats and --trials must be >= 1: received {args.repeats}, {args.trials}")
    runs: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(args.keep or tmp)
        folder.mkdir(parents=True, exist_ok=True)
        for i in range(args.repeats):
            for on in ((True, False) if i % 2 == 0 else (False, True)):
                runs.append(run_search(args, folder / f"{'on' if on else 'off'}-{i}.h5", on))
    on, off = _medians([r for r in runs if r["continue"]]), _medians([r for r in runs if not r["continue"]])
    print(json.dumps({
        "command": " ".join(_command(args, Path("RUN.h5"), True)[1:]), "repeats": args.repeats,
        "load_avg_1m": os.getloadavg()[0], "end_bytes": end_bytes(args), "runs": runs, "on": on, "off": off,
        "saving": {"sim_s_run": round(1 - on["sim_s_run_per_set"] / off["sim_s_run_per_set"], 3),
                   "cpu_s": round(1 - on["cpu_s_per_set"] / off["cpu_s_per_set"], 3),
                   "trial_wall_s": round(1 - on["trial_wall_s_per_set"] / off["trial_wall_s_per_set"], 3)},
    }, indent=1))


if __name__ == "__main__":
    main()
