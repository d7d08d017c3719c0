"""Does stepping B worlds in one batch buy CPU time? CPU seconds per world and simulated second of MuJoCo
trials run as one batch of B worlds (worker.trial.simulation.simulate_batch: one model, B data, one law over B worlds)
against the same B parameter sets run one at a time, interleaved, set-ups reused.

    python bench/batch_worlds.py [--spine tetraspine] [--controller NAME] [--batches 1,4,8] [--seconds 3]
                                 [--repeats 3]

Prints one JSON object (last line): per B, `single_cpu_s_per_world_sim_s` and `batch_cpu_s_per_world_sim_s`
(medians over --repeats rounds after a warm-up round, each round B fresh seeded random gaits),
`batch_over_single` (below 1: the batch is cheaper per world) and `same_distances` (the batch's worlds give
the single trials' bits, as worker.trial.simulation promises).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from spinefarm.robot.morphology.registry import load_morphology  # noqa: E402
from spinefarm.worker.trial.setup import SetupCache  # noqa: E402
from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, simulate, simulate_batch  # noqa: E402


def one_round(morph, b: int, first_seed: int, cfg: TrialConfig, controller: str | None,
              caches: dict[str, SetupCache]) -> tuple[float, float, bool]:
    """(single, batch) CPU s per world and simulated s over B gaits, and whether their distances agree."""
    seeds = list(range(first_seed, first_seed + b))
    gaits = [random_unit_params(morph, s, controller) for s in seeds]
    t0 = time.process_time()
    single = [simulate(morph, u, cfg, s, controller=controller, setup=caches["single"]).result
              for u, s in zip(gaits, seeds, strict=True)]
    t1 = time.process_time()
    batch = [o.result for o in simulate_batch(morph, gaits, cfg, seeds, controller=controller,
                                               setup=caches["batch"])]
    t2 = time.process_time()
    sim_s = sum(r.sim_time_s for r in single)
    same = [r.distance_m for r in single] == [r.distance_m for r in batch]
    return (t1 - t0) / sim_s, (t2 - t1) / sim_s, same


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spine", default="tetraspine")
    ap.add_argument("--controller", default=None, help="controller space (default: the spine's own)")
    ap.add_argument("--batches", default="1,4,8", help="batch sizes B, separated by commas (default 1,4,8)")
    ap.add_argument("--seconds", type=float, default=3.0, help="simulated seconds per trial (default 3)")
    ap.add_argument("--repeats", type=int, default=3, help="rounds per B after a warm-up round (default 3)")
    args = ap.parse_args()
    try:
        sizes = [int(b) for b in args.batches.split(",")]
    except ValueError:
        sys.exit(f"batch_worlds: --batches {args.batches!r}: expected whole numbers separated by commas")
    if not sizes or min(sizes) < 1:
        sys.exit(f"batch_worlds: --batches {args.batches!r}: expected sizes of at least 1")
    morph = load_morphology(args.spine)
    cfg = TrialConfig(duration_s=args.seconds, engine="mujoco")
    out = {}
    for b in sizes:
        caches = {"single": SetupCache(), "batch": SetupCache()}
        rows = [one_round(morph, b, 1 + r * b, cfg, args.controller, caches) for r in range(args.repeats + 1)][1:]
        single, batch = (float(np.median([row[k] for row in rows])) for k in (0, 1))
        out[str(b)] = {"single_cpu_s_per_world_sim_s": single, "batch_cpu_s_per_world_sim_s": batch,
                       "batch_over_single": batch / single, "same_distances": all(row[2] for row in rows)}
        print(f"B={b}: single {single:.4f}, batch {batch:.4f} CPU s per world and simulated s", file=sys.stderr)
    print(json.dumps({"spine": args.spine, "controller": args.controller, "seconds": args.seconds,
                      "repeats": args.repeats, "batches": out}))


if __name__ == "__main__":
    main()
