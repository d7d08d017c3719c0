"""Speed against error of the physics step: the same seeded parameter sets at several steps.

For each of N seeded random parameter sets, runs the trial at dt = 2, 1, 0.5, 0.25 ms and at a
0.125 ms reference, and prints per step: the relative error of the final distance (robot COM,
ground plane) and of the COT against the reference, the wall time per simulated second, and the
status. The last line is one JSON object; `recommended_dt_s` is the largest step whose median
distance error is <= 1 %.

    python bench/accuracy.py [--morphology tetraspine] [--duration 30] [--seeds 5] [--jobs 2]
"""

from __future__ import annotations

import argparse
import json
from concurrent.futures import ProcessPoolExecutor
from statistics import median

from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.worker.tools.accuracy import rel
from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, simulate

STEPS_S = (2e-3, 1e-3, 5e-4, 2.5e-4)
REFERENCE_S = 1.25e-4


def one(job: tuple[str, int, float, float, str | None]) -> dict:
    name, seed, dt, duration, controller = job
    morph = load_morphology(name)
    r = simulate(morph, random_unit_params(morph, seed, controller),
                 TrialConfig(duration_s=duration, dt_s=dt, controller=controller), seed).result
    return {"seed": seed, "dt_s": dt, "distance_m": r.distance_m, "cot": r.cot, "status": str(r.status),
            "reason": r.reason, "wall_s_per_sim_s": r.wall_time_s / max(r.sim_time_s, 1e-9)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--morphology", default="tetraspine")
    ap.add_argument("--controller", default=None)
    ap.add_argument("--duration", type=float, default=30.0)
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    seeds = list(range(1, args.seeds + 1))
    jobs = [(args.morphology, s, dt, args.duration, args.controller) for s in seeds for dt in (*STEPS_S, REFERENCE_S)]
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(one, jobs))
    ref = {r["seed"]: r for r in rows if r["dt_s"] == REFERENCE_S}
    table = []
    for dt in STEPS_S:
        mine = [r for r in rows if r["dt_s"] == dt]
        errs = [rel(r["distance_m"], ref[r["seed"]]["distance_m"]) for r in mine]
        cot_errs = [rel(r["cot"], ref[r["seed"]]["cot"]) for r in mine]
        entry = {"dt_s": dt, "median_distance_error": median(errs), "max_distance_error": max(errs),
                 "median_cot_error": median(cot_errs),
                 "wall_s_per_sim_s": median(r["wall_s_per_sim_s"] for r in mine),
                 "failed": sum(r["status"] != "complete" for r in mine),
                 "distance_errors": [round(e, 5) for e in errs]}
        table.append(entry)
        print(f"dt {dt * 1e3:6.3f} ms  median distance error {entry['median_distance_error']:8.4%}  "
              f"max {entry['max_distance_error']:8.4%}  median COT error {entry['median_cot_error']:8.4%}  "
              f"wall/sim {entry['wall_s_per_sim_s']:.3f}  failed {entry['failed']}")
    ok = [e["dt_s"] for e in table if e["median_distance_error"] <= 0.01 and e["failed"] == 0]
    out = {"benchmark": "accuracy", "morphology": args.morphology, "duration_s": args.duration, "seeds": seeds,
           "reference_dt_s": REFERENCE_S,
           "reference": [{k: ref[s][k] for k in ("seed", "distance_m", "cot", "status")} for s in seeds],
           "reference_wall_s_per_sim_s": median(r["wall_s_per_sim_s"] for r in ref.values()),
           "table": table, "recommended_dt_s": max(ok) if ok else None}
    print(json.dumps(out))


if __name__ == "__main__":
    main()
