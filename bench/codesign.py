"""Co-designed search (body and gait) against gait-only search at the same budget, on the paper's Tetraspine.

For each seed the bench runs two searches of the 12-segment Tetraspine with the NTRT controller space and the
`speed` objective: the built-in's fixed body, and the same robot with a `search:` block freeing its rod
lengths, each string tag's stiffness and its rod density (the segment mass) within +-`--spread` of the paper's
values. Trials run in a pool of processes through the worker's own evaluator (each co-designed trial builds and
checks its body; an infeasible one counts as failed). Reported per mode and seed: trials complete and
infeasible, the speed-COT front of the complete trials, and the judge: the front's fastest `--judged` trials
re-run as `--episodes` perturbed episodes (`--randomize`), their median speed and COT, and whether one reaches
the paper's speed (>= 9.46 cm/s) at the paper's COT (<= 3.2) at those medians.

Full run (hours of CPU):  python bench/codesign.py --budget 2000 --seeds 3 --duration 30
Bounded run:              python bench/codesign.py --budget 10 --seeds 3 --duration 2 --episodes 4

Prints one JSON object (last line).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
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


def run_search(pool: ProcessPoolExecutor, source: str, seed: int, args: argparse.Namespace) -> dict:
    from spinefarm.coordinator.problem import build_run_config
    from spinefarm.coordinator.setup import SearchSettings, new_run
    from spinefarm.protocol.results import TrialResult
    from spinefarm.protocol.settings import JudgePolicy

    config = build_run_config(f"bench-{seed}", source, objective="speed", seed=seed, duration_s=args.duration,
                              trial_overrides={"engine": args.engine})
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
    cols = storage.columns()
    ok = np.flatnonzero(cols["status"] == b"complete")
    reasons = [r.decode() for r in cols["reason"]]
    on_front = ok[front(cols["speed_cm_s"][ok], cols["cot"][ok])]
    judged = [judge(pool, config, int(t), cols, args) for t in on_front[:args.judged]]
    return {"complete": int(ok.size), "infeasible": sum(r.startswith("infeasible: ") for r in reasons),
            "failed_other": int(np.sum(cols["status"] == b"failed")) - sum(r.startswith("infeasible: ")
                                                                           for r in reasons),
            "front": [{"trial_id": int(t), "speed_cm_s": float(cols["speed_cm_s"][t]), "cot": float(cols["cot"][t])}
                      for t in on_front],
            "judged": judged,
            "reaches_paper": any(j["median_speed_cm_s"] >= PAPER_SPEED_CM_S and j["median_cot"] <= PAPER_COT
                                 for j in judged)}


def judge(pool: ProcessPoolExecutor, config, tid: int, cols: dict, args: argparse.Namespace) -> dict:
    """The trial's parameters in `--episodes` perturbed worlds: median speed and COT with their spread."""
    from spinefarm.protocol.robust import RobustSpec, parse_randomize

    robust = RobustSpec(episodes=args.episodes, randomize=parse_randomize(args.randomize), statistic="mean")
    perturbed = replace(config, robust=robust.to_dict())
    r = pool.submit(_evaluate, perturbed.to_dict(), tid, cols["params_unit"][tid].tolist(),
                    int(cols["seed"][tid])).result()
    eps = [e for e in r.get("episodes", []) if e.get("status") == "complete"]
    speed = np.array([e["speed_cm_s"] for e in eps]) if eps else np.array([np.nan])
    cot = np.array([e["cot"] for e in eps]) if eps else np.array([np.nan])
    return {"trial_id": tid, "episodes_complete": len(eps), "median_speed_cm_s": float(np.median(speed)),
            "speed_range_cm_s": [float(speed.min()), float(speed.max())], "median_cot": float(np.median(cot)),
            "cot_range": [float(cot.min()), float(cot.max())]}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--budget", type=int, default=200, help="trials per search")
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--duration", type=float, default=10.0, help="simulated seconds per trial")
    p.add_argument("--workers", type=int, default=2, help="trials in flight (pool processes)")
    p.add_argument("--spread", type=float, default=0.3, help="body constants free within +-spread")
    p.add_argument("--sampler", default="cmaes")
    p.add_argument("--engine", default="bullet")
    p.add_argument("--episodes", type=int, default=16, help="perturbed episodes of the judge")
    p.add_argument("--randomize", default="friction=0.1,mass=0.05,start_jitter_cm=0.5")
    p.add_argument("--judged", type=int, default=3, help="front trials (fastest first) the judge re-runs")
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        spec = Path(tmp) / "codesign-tetraspine.yaml"
        spec.write_text(search_block(args.spread))
        out: dict = {"command": " ".join(["python", "bench/codesign.py", *sys.argv[1:]]), "budget": args.budget,
                     "duration_s": args.duration, "spread": args.spread, "sampler": args.sampler,
                     "episodes": args.episodes, "randomize": args.randomize,
                     "paper": {"speed_cm_s": PAPER_SPEED_CM_S, "cot": PAPER_COT}, "gait_only": [], "codesign": []}
        with ProcessPoolExecutor(args.workers) as pool:
            for seed in range(args.seeds):
                out["gait_only"].append(run_search(pool, "tetraspine", seed, args))
                out["codesign"].append(run_search(pool, str(spec), seed, args))
                print(json.dumps({"seed": seed, "gait_only": out["gait_only"][-1]["front"][:3],
                                  "codesign": out["codesign"][-1]["front"][:3]}), file=sys.stderr, flush=True)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
