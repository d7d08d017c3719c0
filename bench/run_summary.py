"""What a finished search spent and found, from its run file alone (docs/performance.md's paper-size search).

    python bench/run_summary.py RUN.h5

Prints one JSON object: per rung the evaluations, simulated seconds (settle included) and worker wall seconds
per simulated second; the fidelities the trials ran at (engine and step, with the first trial of each: a raised
fidelity shows as a second one); the judged bests in trial order (screen and judge distances, ratio, verdict);
the share of the workers' time the trials took (their wall time against workers x the time from the run's
start to its last result); the first full-length trial screened, and the first judged, past the paper's
speed; the best judged.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from spinefarm import load_run  # noqa: E402
from spinefarm.storage.hdf5_reader import read_meta  # noqa: E402


def summary(path: Path, paper_speed_cm_s: float, workers: int) -> dict:
    df = load_run(path)
    started = read_meta(path).created_at_unix_s
    simulated = df.sim_time_s + df.settle_s.fillna(0.0)
    out: dict = {"file": str(path), "evaluations": len(df), "failed": int((df.status != "complete").sum()),
                 "rungs": {}}
    for rung, rows in df.groupby("rung"):
        sim_s = float(simulated[rows.index].sum())
        out["rungs"][int(rung)] = {"evaluations": len(rows), "simulated_s": sim_s,
                                   "worker_wall_s_per_sim_s": float(rows.wall_time_s.sum()) / sim_s}
    ran = df[df.status == "complete"]
    groups = sorted(ran.groupby(["engine", "dt_s"], dropna=False), key=lambda g: g[1].index[0])  # a NaN step too
    out["fidelities"] = [{"engine": str(e), "dt_s": float(dt), "trials": len(rows), "first_trial": int(rows.index[0])}
                         for (e, dt), rows in groups]
    elapsed_s = float(df.finished_at_unix_s.max() - started)
    out["last_result_after_s"] = elapsed_s
    out["trials_share_of_worker_time"] = float(df.wall_time_s.sum()) / (workers * elapsed_s)
    judged = df[df.verification.isin(["judged", "holds", "moved", "diverged", "not_reproduced"])]
    out["judged"] = [{"trial": int(t), "after_min": round((r.finished_at_unix_s - started) / 60, 2),
                      "screen_m": round(float(r.distance_m), 4), "judge_m": round(float(r.verify_distance_m), 4),
                      "ratio": round(float(r.judge_ratio), 3), "verdict": str(r.verification)}
                     for t, r in judged.iterrows()]
    full = df[(df.rung == df.rung.max()) & (df.status == "complete")]
    fast = full[full.speed_cm_s > paper_speed_cm_s]
    if len(fast):
        t = int(fast.index[0])
        out["first_screened_past_paper"] = {"trial": t, "after_min": (df.finished_at_unix_s[t] - started) / 60}
    judged_speed = judged.verify_distance_m / judged.sim_time_s * 100.0
    past = judged[judged_speed > paper_speed_cm_s]
    if len(past):
        out["first_judged_past_paper"] = {"trial": int(past.index[0]), "judge_m": float(past.verify_distance_m.iloc[0])}
    # a diverged judge run (older files: not reproduced) never counts; a moved set counts by its judged distance
    counted = judged[~judged.verification.isin(["diverged", "not_reproduced"])]
    if len(counted):
        t = int(counted.verify_distance_m.idxmax())
        out["best_judged"] = {"trial": t, "screen_m": float(df.distance_m[t]),
                              "judge_m": float(df.verify_distance_m[t]),
                              "speed_cm_s": float(judged_speed[t])}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--paper-speed", type=float, default=9.46, help="cm/s (default: the paper's Tetraspine)")
    ap.add_argument("--workers", type=int, default=2, help="workers the search ran (default 2)")
    args = ap.parse_args()
    print(json.dumps(summary(args.run, args.paper_speed, args.workers), indent=1))


if __name__ == "__main__":
    main()
