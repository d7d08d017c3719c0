"""Co-designed search (body and gait) against gait-only search at the same budget, on the paper's Tetraspine.

For each seed the bench runs two searches of the 12-segment Tetraspine with a controller space (`--controller`,
default NTRT's) and the `speed` objective: the built-in's fixed body, and the same robot with a `search:` block
freeing its rod lengths, each string tag's stiffness and its rod density (the segment mass) within +-`--spread`
of the paper's values. Trials run in a pool of processes through the worker's own evaluator (each co-designed
trial builds and checks its body; an infeasible one counts as failed), screened in `--engine` (with `--dt` and
`--engine-option`, e.g. MuJoCo at 2 ms without segment contacts, the cheap tier). Reported per mode and seed:
trials complete and infeasible, the speed-COT front of the complete trials, and the judge: the `--judged` front
trials nearest the paper's point (least max(9.46 / speed, COT / 3.2)) re-run in `--judge-engine` at its own step
as `--episodes` perturbed episodes (`--randomize`), their median speed and COT with their range, and whether one
reaches the paper's speed (>= 9.46 cm/s) at the paper's COT (<= 3.2) at those medians.

Measured run (docs/results.md; sized for ~50 min on a shared 2-core machine):
    nice -n 10 python bench/codesign.py --budget 100 --seeds 2 --duration 5 --controller sidewinding \
        --engine mujoco --dt 0.002 --engine-option segment_contacts=off --judged 1 --episodes 16
Smoke run:  python bench/codesign.py --budget 10 --seeds 3 --duration 2 --episodes 4 --judged 2

Prints one JSON object (last line).
"""

from __future__ import annotations

import argparse
import json
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


def run_config(source: str, seed: int, args: argparse.Namespace, engine: str, screen: bool):
    """The run object of one search (screen: `--engine` with `--dt`, `--engine-option`) or of its judge."""
    from spinefarm.cli.sim_commands import parse_engine_options
    from spinefarm.coordinator.problem import build_run_config

    overrides: dict = {"engine": engine}
    if screen:
        overrides |= {"dt_s": args.dt, "engine_options": parse_engine_options(args.engine_option)}
    return build_run_config(f"bench-{seed}", source, objective="speed", seed=seed, duration_s=args.duration,
                            controller=args.controller, trial_overrides=overrides)


def run_search(pool: ProcessPoolExecutor, source: str, seed: int, args: argparse.Namespace) -> dict:
    from spinefarm.coordinator.setup import SearchSettings, new_run
    from spinefarm.protocol.results import TrialResult
    from spinefarm.protocol.settings import JudgePolicy

    started = time.monotonic()
    config = run_config(source, seed, args, args.engine, screen=True)
    core, storage = new_run(config, SearchSettings(trials=args.budget, sampler=args.sampler,
                                                   judge=JudgePolicy(enabled=False)), None)
    done = 0
    while done < args.budget:
        batch = [t for t in (core.study.ask() for _ in range(args.workers)) if t is not None]
        cols = storage.columns()
        futures = [pool.submit(_evaluate, config.to_dict(), t, cols["params_unit"][t].tolist(), int(cols["seed"][t]))
                   for t in batch]
        for t, fut in zip(batch, futures, strict=True):
            core.study.tell(replace(TrialResult.from_dict(fut.result()), trial_id=t, worker_id="bench"))
            done += 1
    screen_s = time.monotonic() - started
    cols = storage.columns()
    ok = np.flatnonzero(cols["status"] == b"complete")
    infeasible = sum(r.decode().startswith("infeasible: ") for r in cols["reason"])
    on_front = [int(t) for t in ok[front(cols["speed_cm_s"][ok], cols["cot"][ok])]]
    picked = nearest_paper(cols["speed_cm_s"], cols["cot"], on_front, args.judged)
    judged = judge(pool, run_config(source, seed, args, args.judge_engine, screen=False), picked, cols, args)
    return {"complete": int(ok.size), "infeasible": infeasible,
            "failed_other": int(np.sum(cols["status"] == b"failed")) - infeasible,
            "front": [{"trial_id": t, "speed_cm_s": float(cols["speed_cm_s"][t]), "cot": float(cols["cot"][t]),
                       **body_of(config, cols, t)} for t in on_front],
            "judged": judged,
            "reaches_paper": any(j["median_speed_cm_s"] >= PAPER_SPEED_CM_S and j["median_cot"] <= PAPER_COT
                                 for j in judged),
            "screen_wall_s": round(screen_s, 1), "judge_wall_s": round(time.monotonic() - started - screen_s, 1)}


def body_of(config, cols: dict, tid: int) -> dict:
    """A co-designed trial's body constants by name (the `body.` parameters), empty for a fixed body."""
    names = [p["name"] for p in config.param_space]
    return {"body": {n[len("body."):]: float(cols["params"][tid][i]) for i, n in enumerate(names)
                     if n.startswith("body.")}} if any(n.startswith("body.") for n in names) else {}


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


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--budget", type=int, default=200, help="trials per search")
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--modes", default="gait_only,codesign", help="the searches per seed (comma-separated)")
    p.add_argument("--first-seed", type=int, default=0, help="seeds first-seed .. first-seed + seeds - 1 (several "
                                                                 "processes may share the seeds)")
    p.add_argument("--duration", type=float, default=10.0, help="simulated seconds per trial")
    p.add_argument("--workers", type=int, default=2, help="trials in flight (pool processes)")
    p.add_argument("--spread", type=float, default=0.3, help="body constants free within +-spread")
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
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        spec = Path(tmp) / "codesign-tetraspine.yaml"
        spec.write_text(search_block(args.spread))
        out: dict = {"command": " ".join(["python", "bench/codesign.py", *sys.argv[1:]]), "budget": args.budget,
                     "duration_s": args.duration, "spread": args.spread, "sampler": args.sampler,
                     "controller": args.controller, "engine": args.engine, "dt_s": args.dt,
                     "engine_options": args.engine_option or [],
                     "judge_engine": args.judge_engine,
                     "episodes": args.episodes, "randomize": args.randomize,
                     "paper": {"speed_cm_s": PAPER_SPEED_CM_S, "cot": PAPER_COT}, "gait_only": [], "codesign": []}
        with ProcessPoolExecutor(args.workers) as pool:
            for seed in range(args.first_seed, args.first_seed + args.seeds):
                for mode, source in (("gait_only", "tetraspine"), ("codesign", str(spec))):
                    if mode not in args.modes.split(","):
                        continue
                    out[mode].append(run_search(pool, source, seed, args))
                    # each search as it ends: a run cut short keeps what it measured
                    print(json.dumps({"seed": seed, "mode": mode, **out[mode][-1]}), file=sys.stderr, flush=True)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
