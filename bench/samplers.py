"""Samplers side by side on the paper's spines: verified best speed after a number of trials.

For every sampler, run seed and problem (a morphology with its controller space) the bench runs one
search with the coordinator's study (the sampler, an in-memory storage, the `speed` objective) and a
pool of worker processes running real trials, `--workers` trials in flight as with several workers
(results arrive out of order). At each checkpoint (trials finished) the best trial so far is
re-simulated at a 4x finer step (the run's verification); a best that does not hold within 5 % is
replaced by the next best. Reported per sampler and problem: the verified best speed at each
checkpoint (median, min, max over seeds) and the trials each seed needed before a trial reached 80 %
of the paper's speed (null: not within the budget).

On the fast tier (`--engine mujoco`) the screen ranks and the judge measures, as in a multi-fidelity
search: the three best trials by screen speed are re-simulated in Bullet at its converged step
(`--judge-dt`, 0.25 ms) and the best judged speed is the verified best; the 80 % mark counts only a
trial whose judged speed reaches it (new screen bests past the mark are judged, as a search judges its new
bests).

Full run (hours of CPU):  python bench/samplers.py
Bounded run:              python bench/samplers.py --budget 40 --checkpoints 20,40 --seeds 5 --duration 4

    --problems tetraspine:sidewinding,tetrahedral-complex:ntrt   morphology:controller pairs
    --samplers paper,cmaes,tpe    --seeds 5    --budget 1000    --checkpoints 100,300,1000
    --duration S (default: each morphology's trial length)    --workers 2    --engine bullet
    --settle S    --dt S    --engine-option KEY=VALUE (repeatable)    --judge-dt 0.00025

Prints one JSON object (last line).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from spinefarm.cli import checks
from spinefarm.cli.sim_commands import add_engine_option_argument, trial_overrides
from spinefarm.protocol.results import TrialResult

# The paper's table (speed cm/s) for the 80 % mark.
PAPER_SPEED_CM_S = {"tetraspine": 9.46, "tetrahedral-complex": 6.13, "octahedral-complex": 4.6, "ribbed": 5.37}


def _trial(morphology: str, controller: str | None, trial_config: dict, params_unit: list, seed: int):
    from spinefarm.worker.trial.simulation import TrialConfig, simulate

    return simulate(morphology, np.asarray(params_unit), TrialConfig.from_dict(trial_config), seed,
                    controller=controller).result


def _verify(morphology: str, controller: str | None, trial_config: dict, params_unit: list, seed: int,
            distance_m: float) -> dict:
    from spinefarm.worker.tools.verify import VerifySettings, verify_trial
    from spinefarm.worker.trial.simulation import TrialConfig

    return verify_trial(morphology, np.asarray(params_unit), TrialConfig.from_dict(trial_config), seed,
                        distance_m, VerifySettings(tolerance=0.05),  # the 5 % its documented figures used
                        controller=controller).to_dict()


def _judge(morphology: str, controller: str | None, trial_config: dict, params_unit: list, seed: int,
           judge_dt_s: float) -> dict:
    """The Bullet judge's run of a screened trial at its converged step."""
    from spinefarm.worker.trial.simulation import TrialConfig, simulate

    cfg = TrialConfig.from_dict({**trial_config, "engine": "bullet", "engine_options": {}, "dt_s": judge_dt_s,
                                 "auto_dt": False})
    r = simulate(morphology, np.asarray(params_unit), cfg, seed, controller=controller).result
    return {"holds": bool(r.ok), "speed_cm_s": float(r.speed_cm_s), "distance_m": float(r.distance_m)}


@dataclass(frozen=True)
class Bench:
    """What every search of one bench run shares: trials per search, checkpoints (trials finished),
    simulated seconds per trial (None: the morphology's), engine, trials in flight, trial config
    overrides (settle_s, dt_s, engine_options) and the Bullet judge's step for a screened search."""

    budget: int
    checkpoints: tuple[int, ...]
    duration_s: float | None
    engine: str
    workers: int
    overrides: dict
    judge_dt_s: float = 0.00025


class _Search:
    """One search of the bench: the study asks, the pool runs `workers` trials at once, a judge (or the run's
    verification) checks the best ones. Verdicts are kept by trial id, so a trial is judged once."""

    def __init__(self, pool: ProcessPoolExecutor, bench: Bench, morphology: str, controller: str | None,
                 sampler: str, seed: int) -> None:
        from spinefarm.coordinator.problem import build_run_config
        from spinefarm.coordinator.setup import SearchSettings, new_run
        from spinefarm.protocol.settings import JudgePolicy

        overrides = {**bench.overrides, **({"engine": bench.engine} if bench.engine != "bullet" else {})} or None
        self.pool, self.controller, self.judge_dt_s = pool, controller, bench.judge_dt_s
        self.screened = bench.engine != "bullet"
        self.config = build_run_config(f"bench-{sampler}-{seed}", morphology, objective="speed", seed=seed,
                                       controller=controller, duration_s=bench.duration_s, trial_overrides=overrides)
        core, self.storage = new_run(self.config, SearchSettings(trials=bench.budget, sampler=sampler,
                                                                 judge=JudgePolicy(enabled=False)), None)
        self.study = core.study
        self.target = 0.8 * PAPER_SPEED_CM_S.get(morphology, float("nan"))
        self.running: dict = {}
        self.verdicts: dict[int, dict] = {}
        self.screen_best = -np.inf

    def _args(self, tid: int) -> tuple:
        cols = self.storage.columns()
        return (self.config.morphology_spec, self.controller, self.config.trial_config,
                cols["params_unit"][tid].tolist(), int(cols["seed"][tid]))

    def submit(self) -> None:
        tid = self.study.ask()
        if tid is not None:
            self.running[self.pool.submit(_trial, *self._args(tid))] = tid

    def tell(self, fut) -> TrialResult:
        tid = self.running.pop(fut)
        result = fut.result()
        self.study.tell(replace(result, trial_id=tid, worker_id="bench"))
        return result

    def judge(self, tid: int) -> dict:
        if tid not in self.verdicts:
            args = self._args(tid)
            self.verdicts[tid] = (self.pool.submit(_judge, *args, self.judge_dt_s) if self.screened else
                                  self.pool.submit(_verify, *args,
                                                   float(self.storage.columns()["distance_m"][tid]))).result()
        return self.verdicts[tid]

    def verified_best(self, n: int) -> float | None:
        cols = self.storage.columns()
        done = np.flatnonzero(cols["status"][:n] == b"complete")
        best3 = done[np.argsort(-cols["objective"][done], kind="stable")][:3]
        for tid in best3:
            self.judge(int(tid))
        if self.screened:  # the judge's speed counts; the best of the three judged
            held = [self.verdicts[int(t)] for t in done if int(t) in self.verdicts and self.verdicts[int(t)]["holds"]]
            return max((v["speed_cm_s"] for v in held), default=None)
        for tid in best3:
            if self.verdicts[int(tid)]["holds"]:
                return float(cols["speed_cm_s"][int(tid)])
        return None

    def reaches_target(self, tid: int, result: TrialResult) -> bool:
        """A new best past the mark (as the search's own verification, only new bests are judged)."""
        if not (result.ok and result.speed_cm_s >= self.target and result.speed_cm_s > self.screen_best):
            return False
        self.screen_best = result.speed_cm_s
        if not self.screened:
            return True
        v = self.judge(tid)
        return v["holds"] and v["speed_cm_s"] >= self.target

    def finish_first(self, n: int) -> int:
        """Wait for every trial among the first n still running; how many were finished."""
        told = 0
        while self.storage.columns()["status"][:n].tolist().count(b"waiting"):
            self.tell(next(iter(self.running)))
            told += 1
        return told


def search(pool: ProcessPoolExecutor, bench: Bench, morphology: str, controller: str | None, sampler: str,
           seed: int) -> dict:
    run = _Search(pool, bench, morphology, controller, sampler, seed)
    out: dict = {"seed": seed, "best_verified_speed_cm_s": {}, "trials_to_80pct": None}
    finished = 0
    t0 = time.perf_counter()
    for _ in range(bench.workers):
        run.submit()
    while run.running:
        done, _ = wait(list(run.running), return_when=FIRST_COMPLETED)
        for fut in done:
            tid = run.running[fut]
            result = run.tell(fut)
            finished += 1
            if out["trials_to_80pct"] is None and run.reaches_target(tid, result):
                out["trials_to_80pct"] = finished
            if finished in bench.checkpoints:
                # checkpoints count trials in id order: the first n trials are the ones sampled first
                n = finished
                finished += run.finish_first(n)
                out["best_verified_speed_cm_s"][str(n)] = run.verified_best(n)
            run.submit()
    out["wall_time_s"] = time.perf_counter() - t0
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--problems", default="tetraspine:sidewinding,tetrahedral-complex:ntrt",
                    help="morphology:controller pairs, comma-separated")
    ap.add_argument("--samplers", default="paper,cmaes,tpe", help="the samplers compared, comma-separated")
    ap.add_argument("--seeds", type=checks.seed, default=5, help="searches per sampler and problem (seeds 0..N-1)")
    ap.add_argument("--budget", type=int, default=1000, help="trials per search")
    ap.add_argument("--checkpoints", default="100,300,1000", help="trials finished at which the best is judged")
    ap.add_argument("--duration", type=float, default=None,
                    help="simulated seconds per trial (default: each morphology's trial length)")
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--engine", default="bullet")
    ap.add_argument("--settle", type=float, default=None, help="settle phase before scoring (s)")
    ap.add_argument("--dt", default=None, help="the engine's step (default: the engine's own; auto: the stable step)")
    add_engine_option_argument(ap)
    ap.add_argument("--judge-dt", type=float, default=0.00025, help="Bullet judge's step for a screened search")
    ap.add_argument("--runs", action="store_true", help="also print every seed's run")
    args = ap.parse_args()
    # the flags `spinefarm search` shares, read as it reads them (engine options as JSON values)
    overrides = {k: v for k, v in trial_overrides(args).items() if k != "engine"}
    checkpoints = tuple(sorted(int(c) for c in args.checkpoints.split(",") if int(c) <= args.budget))
    bench = Bench(args.budget, checkpoints, args.duration, args.engine, args.workers, overrides, args.judge_dt)
    t0 = time.perf_counter()
    report: dict = {"budget": args.budget, "seeds": args.seeds, "duration_s": args.duration, "engine": args.engine,
                    "trial_overrides": overrides, "judge_dt_s": args.judge_dt if args.engine != "bullet" else None,
                    "workers": args.workers, "paper_speed_cm_s": PAPER_SPEED_CM_S, "problems": {}}
    with ProcessPoolExecutor(args.workers) as pool:
        for problem in args.problems.split(","):
            morphology, _, controller = problem.partition(":")
            rows = report["problems"].setdefault(problem, {})
            for sampler in args.samplers.split(","):
                runs = [search(pool, bench, morphology, controller or None, sampler, seed)
                        for seed in range(args.seeds)]
                summary: dict = {"best_verified_speed_cm_s": {},
                                 "trials_to_80pct": [r["trials_to_80pct"] for r in runs],
                                 "wall_time_s": sum(r["wall_time_s"] for r in runs)}
                for c in checkpoints:
                    v = [r["best_verified_speed_cm_s"].get(str(c)) for r in runs]
                    got = [x for x in v if x is not None]
                    summary["best_verified_speed_cm_s"][str(c)] = {
                        "median": float(np.median(got)) if got else None,
                        "min": min(got) if got else None, "max": max(got) if got else None,
                        "not_verified": len(v) - len(got)}
                if args.runs:
                    summary["runs"] = runs
                rows[sampler] = summary
                print(json.dumps({problem: {sampler: summary}}), file=sys.stderr, flush=True)
    report["wall_time_s"] = time.perf_counter() - t0
    print(json.dumps(report))


if __name__ == "__main__":
    main()
