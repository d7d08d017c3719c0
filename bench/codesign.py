"""Co-designed search (body and gait) against gait-only search at the same budget, on the paper's Tetraspine.

For each seed the bench runs two searches of the 12-segment Tetraspine with a controller space (`--controller`,
default NTRT's) and an objective (`--objective`, default `speed`): the built-in's fixed body, and the same robot
with a `search:` block freeing its rod lengths, each string tag's stiffness and its rod density (the segment
mass) within +-`--spread` of the paper's values. Each search is a real `spinefarm search` (coordinator, Zenoh,
`--workers` worker processes, its run file) screened in `--engine` (with `--dt` and `--engine-option`, e.g.
MuJoCo at 2 ms without segment contacts, the cheap tier), with the multi-fidelity ladder when `--rungs` is given
(successive halving over those durations, `--eta`; the last is the full trial), its own judge off. Reported
per mode and seed: parameter sets complete and infeasible, the speed-COT front of the complete full-length
trials, and the judge: the `--judged` front trials nearest the paper's point (least max(9.46 / speed,
COT / 3.2)) re-run in `--judge-engine` at its own step as `--episodes` perturbed episodes (`--randomize`),
their median speed and COT with their range, and whether one reaches the paper's speed (>= 9.46 cm/s) at the
paper's COT (<= 3.2) at those medians. With `--keep DIR` the run files stay in DIR (`MODE-seedS.h5`, with the
spec file searched) and the first judged trial of each search is exported by `spinefarm export RUN.h5 --gait
(--spec for a co-designed body)` and re-run by `spinefarm trial`: its distance against the stored one.

Measured runs (docs/results.md; ~70 min on the shared 2-core machine at a load of 10-13):
    nice -n 10 python bench/codesign.py --budget 200 --seeds 3 --duration 30 --rungs 5,10,30 --eta 4 \
        --controller sidewinding --engine mujoco --dt 0.002 --engine-option segment_contacts=off \
        --judged 1 --episodes 16 --objective cot:9.46 --keep DIR
    and the small-budget row (then without the ladder, trials in the bench's own process pool):
    nice -n 10 python bench/codesign.py --budget 100 --seeds 2 --duration 5 --controller sidewinding \
        --engine mujoco --dt 0.002 --engine-option segment_contacts=off --judged 1 --episodes 16
Smoke run:  python bench/codesign.py --budget 10 --seeds 1 --duration 2 --episodes 4 --judged 2

Prints one JSON object (last line).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

PAPER_SPEED_CM_S, PAPER_COT = 9.46, 3.2  # the paper's Tetraspine (docs/results.md)
_EVALUATORS: dict = {}


def search_block(spread: float) -> str:
    """The Tetraspine with rod lengths, stiffness and rod density free within +-spread of the paper's."""
    from spinefarm.robot.morphology.registry import load_morphology

    s = load_morphology("tetraspine").structure
    lo, hi = 1.0 - spread, 1.0 + spread
    lines = ["base: tetraspine", "name: codesign-tetraspine", "search:", f"  segments.rod_length_scale: [{lo}, {hi}]"]
    lines += [f"  string_materials.{t}.stiffness_n_per_m: [{lo * m.stiffness_n_per_m!r}, {hi * m.stiffness_n_per_m!r}]"
              for t, m in s.string_materials]
    lines += [f"  rod_materials.{t}.density_kg_per_cm3: [{lo * m.density_kg_per_cm3!r}, {hi * m.density_kg_per_cm3!r}]"
              for t, m in s.rod_materials]
    return "\n".join(lines) + "\n"


def _evaluate(config: dict, tid: int, params_unit: list, seed: int) -> dict:
    """One trial in a pool process, through the worker's evaluator (built once per run config)."""
    from spinefarm.protocol.run import RunConfig
    from spinefarm.protocol.work import TrialAssignment
    from spinefarm.worker.service.evaluators import build_evaluator

    key = json.dumps(config, sort_keys=True)
    if key not in _EVALUATORS:
        _EVALUATORS[key] = build_evaluator(RunConfig.from_dict(config))
    return _EVALUATORS[key](TrialAssignment(tid, 1, tuple(params_unit), seed, 3600.0)).to_dict()


def front(speed: np.ndarray, cot: np.ndarray) -> list[int]:
    """Indices of the speed (max) - COT (min) front, fastest first."""
    order = np.argsort(-speed, kind="stable")
    out, best_cot = [], np.inf
    for i in order:
        if cot[i] < best_cot:
            out.append(int(i))
            best_cot = cot[i]
    return out


def nearest_paper(speed: np.ndarray, cot: np.ndarray, candidates: list[int], k: int) -> list[int]:
    """The k candidates nearest the paper's point: least max(paper speed / speed, COT / paper COT), <= 1 passes."""
    miss = [max(PAPER_SPEED_CM_S / max(float(speed[i]), 1e-9), float(cot[i]) / PAPER_COT) for i in candidates]
    return [candidates[j] for j in np.argsort(miss, kind="stable")[:k]]


def screen_flags(args: argparse.Namespace) -> list[str]:
    """The screen's trial settings as `spinefarm search` / `spinefarm trial` flags."""
    flags = ["--duration", repr(args.duration), "--engine", args.engine]
    flags += ["--dt", repr(args.dt)] if args.dt is not None else []
    flags += [f for o in (args.engine_option or []) for f in ("--engine-option", o)]
    return flags + (["--controller", args.controller] if args.controller else [])


def cli(*argv: str) -> subprocess.CompletedProcess:
    """`spinefarm ARGV` in a process of its own (the product's commands, as a user runs them)."""
    r = subprocess.run([sys.executable, "-m", "spinefarm", *argv], capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"spinefarm {' '.join(argv)} failed ({r.returncode}): {r.stderr.strip()[-2000:]}")
    return r


def screen(source: str, seed: int, mode: str, args: argparse.Namespace, out: Path) -> None:
    """One search, screened: `spinefarm search` with `--workers` workers, its run file at `out`."""
    ladder = ["--rungs", args.rungs, "--eta", str(args.eta)] if args.rungs else []
    cli("search", source, "--trials", str(args.budget), "--workers", str(args.workers), "--seed", str(seed),
        "--objective", args.objective, "--sampler", args.sampler, *screen_flags(args), *ladder, "--no-verify",
        "--run-id", f"codesign-{mode}-{seed}", "--api-port", "-1", "--quiet", "--overwrite", "--out", str(out))


def judge_config(source: str, seed: int, args: argparse.Namespace):
    """The run object of the judge: the search's robot, controller and duration in `--judge-engine` at its step."""
    from spinefarm.coordinator.problem import build_run_config

    return build_run_config(f"judge-{seed}", source, objective=args.objective, seed=seed,
                            duration_s=args.duration, controller=args.controller,
                            trial_overrides={"engine": args.judge_engine})


def run_search(pool: ProcessPoolExecutor, source: str, seed: int, mode: str, args: argparse.Namespace,
               folder: Path) -> dict:
    from spinefarm.storage.hdf5_reader import read_run

    started = time.monotonic()
    out = folder / f"{mode}-seed{seed}.h5"
    screen(source, seed, mode, args, out)
    screen_s = time.monotonic() - started
    meta, raw = read_run(out)
    cols = {k: np.asarray(raw[k]) for k in ("status", "reason", "rung", "speed_cm_s", "cot", "seed")}
    n = cols["status"].size
    cols["params_unit"] = np.asarray(raw["params_unit"], dtype=float).reshape(n, meta.n_params)
    cols["params"] = np.asarray(raw["params"], dtype=float).reshape(n, meta.n_params)
    first, last = cols["rung"] == 0, cols["rung"] == cols["rung"].max()
    ok = np.flatnonzero(last & (cols["status"] == b"complete"))
    infeasible = int(sum(r.decode().startswith("infeasible: ") for r in cols["reason"][first]))
    on_front = [int(t) for t in ok[front(cols["speed_cm_s"][ok], cols["cot"][ok])]]
    picked = nearest_paper(cols["speed_cm_s"], cols["cot"], on_front, args.judged)
    config = judge_config(source, seed, args)
    judged = judge(pool, config, picked, cols, args)
    names = list(meta.param_names)
    result = {"run_file": str(out) if args.keep else None, "parameter_sets": int(first.sum()),
              "evaluations": n, "full_length_complete": int(ok.size),
              "complete": int(np.sum(first & (cols["status"] == b"complete"))), "infeasible": infeasible,
              "failed_other": int(np.sum(first & (cols["status"] == b"failed"))) - infeasible,
              "front": [{"trial_id": t, "speed_cm_s": float(cols["speed_cm_s"][t]), "cot": float(cols["cot"][t]),
                         **body_of(names, cols, t)} for t in on_front],
              "judged": judged,
              "reaches_paper": any(j["median_speed_cm_s"] >= PAPER_SPEED_CM_S and j["median_cot"] <= PAPER_COT
                                   for j in judged),
              "screen_wall_s": round(screen_s, 1), "judge_wall_s": round(time.monotonic() - started - screen_s, 1)}
    if args.keep and picked:
        result["exported"] = export(out, picked[0], int(cols["seed"][picked[0]]), mode, seed, args)
    return result


def body_of(names: list[str], cols: dict, tid: int) -> dict:
    """A co-designed trial's body constants by name (the `body.` parameters), empty for a fixed body."""
    body = {n[len("body."):]: float(cols["params"][tid][i]) for i, n in enumerate(names) if n.startswith("body.")}
    return {"body": body} if body else {}


def export(run_file: Path, tid: int, trial_seed: int, mode: str, seed: int, args: argparse.Namespace) -> dict:
    """`spinefarm export` of trial `tid` (its gait, and its body as a robot file when co-designed), then
    `spinefarm trial` of what was exported: its distance beside the stored one."""
    from spinefarm.storage.hdf5_reader import read_run

    stem = run_file.parent / f"{mode}-seed{seed}-trial{tid}"
    gait, spec = Path(f"{stem}-gait.json"), Path(f"{stem}-body.yaml")
    body = ["--spec", str(spec)] if mode == "codesign" else []
    cli("export", str(run_file), *body, "--gait", str(gait), "--trial", str(tid))
    robot = str(spec) if body else "tetraspine"
    rerun = json.loads(cli("trial", robot, "--params", str(gait), "--seed", str(trial_seed), *screen_flags(args),
                           "--json").stdout)
    stored = float(np.asarray(read_run(run_file)[1]["distance_m"])[tid])
    return {"trial_id": tid, "seed": trial_seed, "gait": str(gait), "spec": str(spec) if body else None,
            "stored_distance_m": stored, "rerun_distance_m": rerun["distance_m"],
            "bit_for_bit": rerun["distance_m"] == stored}


def judge(pool: ProcessPoolExecutor, config, tids: list[int], cols: dict, args: argparse.Namespace) -> list[dict]:
    """The trials' parameters in `--episodes` perturbed worlds: median speed and COT with their range. Each
    trial's episodes are split over the pool (chunk c draws its worlds from the trial's seed + c), all at once."""
    from spinefarm.protocol.robust import RobustSpec, parse_randomize

    chunks = np.array_split(np.arange(args.episodes), min(args.workers, args.episodes))
    futures = {}
    for t in tids:
        for c, part in enumerate(chunks):
            robust = RobustSpec(episodes=len(part), randomize=parse_randomize(args.randomize), statistic="mean")
            perturbed = replace(config, robust=robust.to_dict()).to_dict()
            futures[t, c] = pool.submit(_evaluate, perturbed, t, cols["params_unit"][t].tolist(),
                                        int(cols["seed"][t]) + c)
    out = []
    for tid in tids:
        eps = [e for c in range(len(chunks)) for e in futures[tid, c].result().get("episodes", [])
               if e.get("status") == "complete"]
        speed = np.array([e["speed_cm_s"] for e in eps]) if eps else np.array([np.nan])
        cot = np.array([e["cot"] for e in eps]) if eps else np.array([np.nan])
        out.append({"trial_id": tid, "episodes_complete": len(eps), "median_speed_cm_s": float(np.median(speed)),
                    "speed_range_cm_s": [float(speed.min()), float(speed.max())],
                    "median_cot": float(np.median(cot)), "cot_range": [float(cot.min()), float(cot.max())]})
    return out


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--budget", type=int, default=200, help="parameter sets per search (`search --trials`)")
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--modes", default="gait_only,codesign", help="the searches per seed (comma-separated)")
    p.add_argument("--first-seed", type=int, default=0, help="seeds first-seed .. first-seed + seeds - 1 (several "
                                                                 "processes may share the seeds)")
    p.add_argument("--duration", type=float, default=10.0, help="simulated seconds per full-length trial")
    p.add_argument("--rungs", default=None, metavar="S,S,...",
                   help="screening durations of the ladder (successive halving), the last = --duration")
    p.add_argument("--eta", type=int, default=3, help="the ladder's promotion ratio: the best 1/eta go on")
    p.add_argument("--workers", type=int, default=2, help="worker processes (and the judge's pool)")
    p.add_argument("--spread", type=float, default=0.3, help="body constants free within +-spread")
    p.add_argument("--objective", default="speed", help="the searches' objective, e.g. speed or cot:9.46")
    p.add_argument("--sampler", default="cmaes")
    p.add_argument("--controller", default=None, help="controller space (default: the robot's, NTRT's 116)")
    p.add_argument("--engine", default="bullet", help="engine of the search's trials (the screen)")
    p.add_argument("--dt", type=float, default=None, help="the screen's physics step (default: the engine's)")
    p.add_argument("--engine-option", action="append", default=None, metavar="KEY=VALUE",
                   help="the screen engine's option (repeatable), e.g. segment_contacts=off")
    p.add_argument("--judge-engine", default="bullet", help="engine of the judge's episodes (at its own step)")
    p.add_argument("--episodes", type=int, default=16, help="perturbed episodes of the judge")
    p.add_argument("--randomize", default="friction=0.1,mass=0.05,start_jitter_cm=0.5")
    p.add_argument("--judged", type=int, default=3,
                   help="front trials the judge re-runs (nearest the paper's point first)")
    p.add_argument("--keep", type=Path, default=None, metavar="DIR",
                   help="keep each search's run file (and the spec searched) in DIR; export and re-run the judged")
    args = p.parse_args()
    if args.rungs and float(args.rungs.split(",")[-1]) != args.duration:
        p.error(f"--rungs {args.rungs}: the last rung must be the full trial, --duration {args.duration}")
    return args


def main() -> int:
    args = parse_args()
    started, load_start = time.monotonic(), os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        spec = folder / "codesign-tetraspine.yaml"
        spec.write_text(search_block(args.spread))
        out: dict = {"command": " ".join(["python", "bench/codesign.py", *sys.argv[1:]]), "budget": args.budget,
                     "duration_s": args.duration, "rungs": args.rungs, "eta": args.eta if args.rungs else None,
                     "spread": args.spread, "objective": args.objective, "sampler": args.sampler,
                     "controller": args.controller, "engine": args.engine, "dt_s": args.dt,
                     "engine_options": args.engine_option or [], "judge_engine": args.judge_engine,
                     "episodes": args.episodes, "randomize": args.randomize,
                     "paper": {"speed_cm_s": PAPER_SPEED_CM_S, "cot": PAPER_COT}, "gait_only": [], "codesign": []}
        with ProcessPoolExecutor(args.workers) as pool:
            for seed in range(args.first_seed, args.first_seed + args.seeds):
                for mode, source in (("gait_only", "tetraspine"), ("codesign", str(spec))):
                    if mode not in args.modes.split(","):
                        continue
                    out[mode].append(run_search(pool, source, seed, mode, args, folder))
                    # each search as it ends: a run cut short keeps what it measured
                    print(json.dumps({"seed": seed, "mode": mode, **out[mode][-1]}), file=sys.stderr, flush=True)
    out |= {"wall_s": round(time.monotonic() - started, 1),
            "load_average_1_5_15": {"start": [round(x, 2) for x in load_start],
                                    "end": [round(x, 2) for x in os.getloadavg()]}}
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
