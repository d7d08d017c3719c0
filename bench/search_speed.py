"""Wall time of a whole search, Bullet only against multi-fidelity (MuJoCo screen, successive halving,
Bullet judge), with the same budget and seed, run side by side on this machine.

    python bench/search_speed.py [--morphology tetraspine] [--controller sidewinding] [--trials 60]
                                 [--duration 30] [--rungs 10,30] [--eta 3] [--workers 2] [--seed 1]
                                 [--screen-dt 0.002] [--screen-option segment_contacts=off]

Both runs are real `spinefarm search` processes (embedded Zenoh, local workers). Each re-simulates its
new bests in Bullet at a converged step (0.25 ms): the Bullet-only run at 4x its own step, the
multi-fidelity run with --verify-engine bullet. Prints one JSON object: wall seconds of each, their
ratio, the Bullet-verified distance and speed of each run's best, and each run file's summary
(bench/run_summary.py: the fidelities its trials ran at, its judged bests). `--keep DIR` keeps the run files.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

from run_summary import summary  # noqa: E402
from samplers import PAPER_SPEED_CM_S  # noqa: E402


def search(label: str, out: Path, args: argparse.Namespace, extra: list[str]) -> dict:
    cmd = [sys.executable, "-m", "spinefarm", "search", args.morphology, "--trials", str(args.trials),
           "--workers", str(args.workers), "--seed", str(args.seed), "--out", str(out), "--api-port", "-1",
           "--quiet", "--settle", str(args.settle), *extra]
    if args.controller:
        cmd += ["--controller", args.controller]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{label} search failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
    from spinefarm.storage.hdf5 import Hdf5Storage

    with Hdf5Storage.open_read(out) as st:
        counts = st.counts()
        cols = st.columns()
        verified = [b for b in st.best(20) if b.verification in ("holds", "judged")]
        best = verified[0] if verified else None
        cpu_sim_s = float(cols["sim_time_s"][cols["status"] == b"complete"].sum())
    return {
        "file": str(out), "summary": summary(out, PAPER_SPEED_CM_S.get(args.morphology, 0.0), args.workers),
        "wall_s": wall, "evaluations": counts["complete"] + counts["failed"], "failed": counts["failed"],
        "simulated_s": cpu_sim_s,
        "best_trial": None if best is None else best.trial_id,
        "best_screen_distance_m": None if best is None else best.distance_m,
        "best_verified_distance_m": None if best is None else best.verify_distance_m,
        "best_verified_speed_cm_s": None if best is None else 100 * best.verify_distance_m / best.sim_time_s,
        "best_cot": None if best is None else best.cot,
    }


def main() -> None:
    from spinefarm.cli import checks  # an argparse type: seeds are whole numbers >= 0

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--morphology", default="tetraspine")
    ap.add_argument("--controller", default="sidewinding")
    ap.add_argument("--trials", type=int, default=60)
    ap.add_argument("--duration", type=float, default=30.0)
    ap.add_argument("--rungs", default=None, help="default: duration/3, duration")
    ap.add_argument("--eta", type=int, default=3)
    ap.add_argument("--settle", type=float, default=1.0, help="settle phase before scoring, both runs (s)")
    ap.add_argument("--screen-dt", type=float, default=0.002,
                    help="MuJoCo's step as a screen (default 2 ms: it ranks, the Bullet judge measures)")
    ap.add_argument("--screen-option", action="append", default=None, metavar="KEY=VALUE",
                    help="MuJoCo engine options of the screen (default segment_contacts=off: no such contact "
                         "formed in any gait measured, and they cost 40 %% of a step)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=checks.seed, default=1)
    ap.add_argument("--keep", type=Path, default=None, metavar="DIR", help="keep the two run files in DIR")
    args = ap.parse_args()
    rungs = args.rungs or f"{args.duration / 3:g},{args.duration:g}"
    if args.keep:
        args.keep.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() if args.keep is None else contextlib.nullcontext(args.keep) as tmp:
        # Bullet named, not left to `auto`: a calibration would add its minutes to this run's wall time.
        bullet = search("bullet", Path(tmp) / "bullet.h5", args,
                        ["--engine", "bullet", "--duration", str(args.duration)])
        options = [x for o in (args.screen_option or ["segment_contacts=off"]) for x in ("--engine-option", o)]
        multi = search("multi-fidelity", Path(tmp) / "multi.h5", args,
                       ["--engine", "mujoco", "--dt", str(args.screen_dt), *options, "--rungs", rungs,
                        "--eta", str(args.eta), "--verify-engine", "bullet"])
    b, m = bullet["best_verified_distance_m"], multi["best_verified_distance_m"]
    print(json.dumps({
        "morphology": args.morphology, "controller": args.controller, "trials": args.trials,
        "duration_s": args.duration, "rungs": rungs, "eta": args.eta, "workers": args.workers, "seed": args.seed,
        "settle_s": args.settle, "screen_dt_s": args.screen_dt,
        "bullet_only": bullet, "multi_fidelity": multi,
        "wall_time_ratio": bullet["wall_s"] / multi["wall_s"],
        "verified_best_ratio": (m / b) if (b and m) else None,
    }, indent=2))


if __name__ == "__main__":
    main()
