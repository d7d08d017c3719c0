"""The CPG at its own step against the CPG at every physics step, per spine and engine.

For seeded random gaits of each spine's controller space (--controller, default its own), whole trials at the engine's
default physics step with the CPG at every step (`cpg_step_s` 0) and with each of --cpg-steps as the cap of the CPG's
own step (worker.control.law: each network at the largest multiple of the physics step within that cap and
SLOW_RATE_STEP over its fastest rate, one RK4 step per update, setpoints interpolated in between), interleaved. Per
spine and CPG step: the relative distance change against every-step (relative to the distance, or to 1 cm for a gait
that barely moves, as docs/accuracy.md), its median and max over the gaits, the CPU seconds per simulated second, and
the spine's chaos floor measured in the same run (every-step trials whose start pose is jittered by 1e-6 cm: the
largest change over the gaits). `within_bar` says whether the median change is within max(1 %, chaos floor), the bar
docs/accuracy.md holds a step to. A spine whose spec fixes the CPG update above the physics step (NTRT's 0.1 s) keeps
it: `spec_fixed` is true and every CPG step gives the every-step bits (`same_bits`).

    python bench/cpg_step.py --spines all --engine mujoco --cpg-steps 0.002,0.004,0.008 [--duration 10] [--gaits 5]
                             [--controller sidewinding]

Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from spinefarm.robot.morphology.registry import builtin_names, load_morphology
from spinefarm.worker.trial.setup import SetupCache
from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, simulate

JITTER_CM = 1e-6


def _change(d: float, base: float) -> float:
    return abs(d - base) / max(abs(base), 1.0) * 100.0


def spine(name: str, engine: str, cpg_steps: list[float], duration_s: float, gaits: int,
          controller: str | None = None) -> dict:
    morph = load_morphology(name)
    base_cfg = TrialConfig(duration_s=duration_s, engine=engine, cpg_step_s=0.0)
    configs = {"every_step": base_cfg, "jitter": TrialConfig(duration_s=duration_s, engine=engine, cpg_step_s=0.0,
                                                            pose_jitter_cm=JITTER_CM)}
    configs.update({f"{s:g}": TrialConfig(duration_s=duration_s, engine=engine, cpg_step_s=s) for s in cpg_steps})
    caches = {k: SetupCache() for k in configs}
    dist: dict[str, list[float]] = {k: [] for k in configs}
    cpu: dict[str, list[float]] = {k: [] for k in configs}
    for g in range(gaits):
        u = random_unit_params(morph, 1 + g, controller)
        for key, cfg in configs.items():
            t0 = time.process_time()
            res = simulate(morph, u, cfg, 1 + g, controller=controller, setup=caches[key]).result
            cpu[key].append((time.process_time() - t0) / res.sim_time_s)
            dist[key].append(res.distance_m * 100.0)
    base = dist["every_step"]
    floor = max(_change(d, b) for d, b in zip(dist["jitter"], base, strict=True))
    bar = max(1.0, floor)
    spec_fixed = morph.control.cpg_update_period_s > base_cfg.step_s * 1.5
    steps = {}
    for s in cpg_steps:
        ch = [_change(d, b) for d, b in zip(dist[f"{s:g}"], base, strict=True)]
        steps[f"{s:g}"] = {"median_change_pct": float(np.median(ch)), "max_change_pct": max(ch),
                           "within_bar": bool(np.median(ch) <= bar), "same_bits": dist[f"{s:g}"] == base,
                           "cpu_s_per_sim_s": float(np.median(cpu[f"{s:g}"][1:] or cpu[f"{s:g}"]))}
    return {"engine": engine, "spec_fixed": bool(spec_fixed), "cpg_update_period_s": morph.control.cpg_update_period_s,
            "chaos_floor_pct": floor, "bar_pct": bar, "distance_cm_every_step": [round(d, 4) for d in base],
            "cpu_s_per_sim_s_every_step": float(np.median(cpu["every_step"][1:] or cpu["every_step"])),
            "cpg_steps": steps}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--spines", default="tetraspine", help="'all' or names, comma-separated")
    ap.add_argument("--engine", default="mujoco")
    ap.add_argument("--cpg-steps", default="0.002,0.004,0.008", help="CPG steps in s, comma-separated")
    ap.add_argument("--duration", type=float, default=10.0, help="simulated seconds per trial")
    ap.add_argument("--gaits", type=int, default=5, help="seeded random gaits per spine")
    ap.add_argument("--controller", default=None, help="controller space of every spine (default: its own)")
    args = ap.parse_args()
    names = builtin_names() if args.spines == "all" else args.spines.split(",")
    steps = [float(s) for s in args.cpg_steps.split(",")]
    t0 = time.time()
    out = {"benchmark": "cpg_step", "duration_s": args.duration, "gaits": args.gaits, "controller": args.controller,
           "spines": {n: spine(n, args.engine, steps, args.duration, args.gaits, args.controller) for n in names}}
    print(json.dumps({**out, "wall_s": time.time() - t0}))


if __name__ == "__main__":
    main()
