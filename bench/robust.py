"""A robust search against a plain one: each search's best measured over fresh perturbed episodes.

Runs two searches of the same robot, sampler and budget (`spinefarm search`, local workers): a plain one, and a
robust one (`--episodes K --randomize ... --robust STAT`: every parameter set scored by a statistic over K
randomised worlds). Then measures each best, and any --gait files given, over M fresh episodes (seeds no search
used) at the full trial length, with the same randomisation: median, quartiles, q25 / median. Prints one JSON
object (last line).

    python bench/robust.py [--trials 300] [--duration 10] [--episodes 8] [--measure-episodes 32] \
        [--gait examples/gaits/tetraspine.json] [--workers 2]

Targets: the robust best's median speed over the 32 fresh episodes >= 9.46 cm/s (the paper's
Tetraspine) with its q25 within 10 % of its median.
"""

from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
PAPER_SPEED_CM_S = 9.46
MEASURE_SEED = 1_000_000_007  # the fresh episodes' seed: no trial of a search has it


def search(out: Path, args: argparse.Namespace, robust: bool, reuse: str | None = None) -> dict:
    """Run one search into `out` (or, given `reuse`, take a finished run file as it is) and read its bests."""
    cmd = [sys.executable, "-m", "spinefarm", "search", args.morphology, "--controller", args.controller,
           "--sampler", args.sampler, "--objective", "speed", "--duration", str(args.duration), "--trials",
           str(args.trials), "--workers", str(args.workers), "--seed", str(args.seed), "--no-verify", "--api-port",
           "-1", "--quiet", "--out", str(out), "--overwrite"]
    for extra in args.search_arg:
        cmd += shlex.split(extra)
    if robust:
        cmd += ["--episodes", str(args.episodes), "--randomize", args.randomize, "--robust", args.statistic]
    t0 = time.perf_counter()
    if reuse:
        out, cmd = Path(reuse), ["", f"(an earlier run: {reuse})"]
    else:
        r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
        if r.returncode != 0:
            sys.exit(f"robust bench: search failed: {r.stderr[-2000:]}")
    from spinefarm.storage.hdf5 import Hdf5Storage

    storage = Hdf5Storage.open_read(out)
    bests = storage.best(args.measure_top)
    meta = storage.run_meta()
    return {"file": str(out), "command": " ".join(cmd[1:]), "wall_time_s": None if reuse else time.perf_counter() - t0,
            "best_trial": bests[0].trial_id, "best_objective": bests[0].objective,
            "best_speed_cm_s": bests[0].speed_cm_s,
            "bests": [{"trial": b.trial_id, "objective": b.objective, "speed_cm_s": b.speed_cm_s,
                       "params": dict(zip(meta.param_names, b.params, strict=True))} for b in bests]}


def measure_one(morphology: str, controller: str, params: dict, randomize: str, k: int, duration_s: float | None
                ) -> dict:
    """Episode k of the fresh measurement (runs in a pool process)."""
    from spinefarm.protocol.robust import RobustSpec, draw_episode, parse_randomize
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.worker.trial.robust import episode_world, run_worlds
    from spinefarm.worker.trial.simulation import TrialConfig

    morph = load_morphology(morphology)
    spec = RobustSpec(episodes=k + 1, randomize=parse_randomize(randomize))
    world = episode_world(morph, TrialConfig(duration_s=duration_s, controller=controller),
                          draw_episode(spec, MEASURE_SEED, k))
    r = run_worlds([world], params, controller)[0]
    return {"episode": k, "status": r.status.value, "speed_cm_s": r.speed_cm_s, "cot": r.cot}


def measure(pool: ProcessPoolExecutor, name: str, morphology: str, controller: str, params: dict,
            args: argparse.Namespace) -> dict:
    import numpy as np

    m = args.measure_episodes
    rows = list(pool.map(measure_one, [morphology] * m, [controller] * m, [params] * m, [args.randomize] * m,
                         range(m), [args.measure_duration] * m))
    speed = np.array([r["speed_cm_s"] for r in rows if r["status"] == "complete"])
    q25, q50, q75 = (float(x) for x in np.percentile(speed, [25, 50, 75])) if speed.size else (np.nan,) * 3
    return {"gait": name, "episodes": m, "failed": m - int(speed.size), "median_speed_cm_s": q50,
            "q25_speed_cm_s": q25, "q75_speed_cm_s": q75, "iqr_speed_cm_s": q75 - q25,
            "q25_over_median": q25 / q50 if q50 else None,
            "median_cot": float(np.median([r["cot"] for r in rows if r["status"] == "complete"])) if speed.size
            else None,
            "meets_target": bool(q50 >= PAPER_SPEED_CM_S and q25 >= 0.9 * q50), "speeds_cm_s": speed.tolist()}


def main() -> None:
    from spinefarm.cli import checks  # an argparse type: seeds are whole numbers >= 0

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--morphology", default="tetraspine")
    ap.add_argument("--controller", default="sidewinding")
    ap.add_argument("--sampler", default="cmaes")
    ap.add_argument("--trials", type=int, default=300, help="parameter sets per search (default 300)")
    ap.add_argument("--duration", type=float, default=10.0, help="search trial length, s (default 10)")
    ap.add_argument("--episodes", default="8",
                    help="episodes per parameter set of the robust search: K, or one K per rung (e.g. 1,2,8)")
    ap.add_argument("--search-arg", action="append", default=[], metavar="ARGS",
                    help="more `spinefarm search` arguments for both searches, e.g. "
                         "'--engine mujoco --rungs 3,10,30' (repeatable)")
    ap.add_argument("--randomize", default="friction=0.1,start_jitter_cm=0.5")
    ap.add_argument("--statistic", default="q25", help="the robust search's --robust (default q25)")
    ap.add_argument("--measure-episodes", type=int, default=32)
    ap.add_argument("--measure-top", type=int, default=1, help="measure each search's K best (default 1)")
    ap.add_argument("--measure-duration", type=float, default=None, help="default: the morphology's (30 s)")
    ap.add_argument("--gait", action="append", default=[], help="also measure this --params gait file")
    ap.add_argument("--seed", type=checks.seed, default=1)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out-dir", default="runs/bench-robust")
    ap.add_argument("--skip-search", action="store_true", help="only measure the --gait files")
    ap.add_argument("--plain-run", metavar="RUN.h5", help="take this finished run as the plain search")
    ap.add_argument("--robust-run", metavar="RUN.h5", help="take this finished run as the robust search")
    args = ap.parse_args()
    t0 = time.perf_counter()
    out_dir = ROOT / args.out_dir
    out_dir.mkdir(parents=True, exist_ok=True)
    searches = {} if args.skip_search else {
        "plain": search(out_dir / "plain.h5", args, robust=False, reuse=args.plain_run),
        "robust": search(out_dir / "robust.h5", args, robust=True, reuse=args.robust_run)}
    from spinefarm.cli.sim_commands import load_params_file

    table = []
    with ProcessPoolExecutor(args.workers) as pool:
        for name, s in searches.items():
            for rank, b in enumerate(s["bests"], 1):
                table.append(measure(pool, f"{name} search best {rank} (trial {b['trial']})", args.morphology,
                                     args.controller, b["params"], args))
        for g in args.gait:
            params, controller = load_params_file(Path(g))
            morphology = json.loads(Path(g).read_text())["morphology"]
            table.append(measure(pool, g, morphology, controller or args.controller, params, args))
    print(json.dumps({"settings": {k: v for k, v in vars(args).items() if k != "gait"}, "gaits": args.gait,
                      "searches": searches, "table": table, "paper_speed_cm_s": PAPER_SPEED_CM_S,
                      "wall_time_s": time.perf_counter() - t0}))


if __name__ == "__main__":
    main()
