"""A ladder chosen by measurement: how well a short rung ranks what the full-length trial finds.

Per spine and seed, --gaits seeded random parameter sets of its controller space run for the full length in the
screening tier (--engine, --dt, --engine-option, --settle, as a search's rungs run them). A rung of length L is
the first L seconds of that trial after the settle (a trial's bits do not depend on its length, so its distance
is read from the full trial's COM path at L, exactly: `prefix_exact` checks one gait against a separate trial of
length L). Per rung length:

- `spearman_rho`: Spearman's rank correlation of the rung's distance with the full length's, per seed
  (median, min);
- `best_survives[eta]`: in how many seeds the full length's best gait is in the rung's top 1/eta (ceil).

Per ladder (rung lengths ending at the full length, each keeping the best 1/eta of the one before, as
synchronous successive halving): `best_survives` (seeds), `sim_s_per_gait` (simulated seconds a gait costs on
average: L1 + L2 / eta + ... ), its saving against every gait at the full length, and
`sim_s_per_gait_continued`: the same were a promoted set continued from the end of its last rung
(L1 + (L2 - L1) / eta + ...). `chosen` is the cheapest
ladder whose best survives in every seed, among those whose first rung ranks with median rho >= --min-rho.

    python bench/ladder.py --spines tetraspine --controller sidewinding --engine mujoco --dt 0.002 \
        --engine-option segment_contacts=off --settle 1 --seeds 3 --gaits 27 --lengths 1,2,3,5,10 --etas 2,3,4

Prints one JSON object. The reference is the screening tier's full-length distance, not the Bullet judge's.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from scipy.stats import spearmanr

from spinefarm.robot.morphology.registry import builtin_names, load_morphology
from spinefarm.worker.trial import scoring
from spinefarm.worker.trial.setup import SetupCache
from spinefarm.worker.trial.simulation import TrialConfig, simulate

_CACHE = SetupCache()


def rung_distances_cm(name: str, controller: str | None, cfg: dict, u: list[float], seed: int,
                      lengths: list[float]) -> list[float]:
    """The planar COM distance (cm) after each of `lengths` seconds of locomotion, from one full trial."""
    morph = load_morphology(name)
    tc = TrialConfig.from_dict(cfg)
    out = simulate(morph, np.array(u), tc, seed, controller=controller, setup=_CACHE)
    path, t = out.com_path_cm, out.com_path_time_s
    start = int(np.argmin(np.abs(t - tc.settle_s)))
    res = []
    for length in lengths:
        i = int(np.argmin(np.abs(t - tc.settle_s - length)))
        ok = abs(t[i] - tc.settle_s - length) < 1e-9 + 0.5 * tc.check_every_s
        res.append(scoring.planar_distance_cm(path[start], path[i]) if ok else float("nan"))
    return res


def rung_table(dist: np.ndarray, lengths: list[float], etas: list[int]) -> dict:
    """dist (seeds, gaits, lengths), the last the full length."""
    table = {}
    for j, length in enumerate(lengths[:-1]):
        rhos = [float(spearmanr(d[:, j], d[:, -1]).statistic) for d in dist]
        surv = {str(eta): int(sum(_in_top(d[:, j], int(np.nanargmax(d[:, -1])), eta) for d in dist)) for eta in etas}
        table[f"{length:g}"] = {"spearman_rho_median": float(np.median(rhos)), "spearman_rho_min": min(rhos),
                                "spearman_rho": rhos, "best_survives": surv}
    return table


def _in_top(values: np.ndarray, index: int, eta: int, among: np.ndarray | None = None) -> bool:
    among = np.arange(len(values)) if among is None else among
    keep = among[np.argsort(-values[among], kind="stable")][:math.ceil(len(among) / eta)]
    return index in keep


def ladders(dist: np.ndarray, lengths: list[float], etas: list[int]) -> list[dict]:
    """Every ladder of up to three rungs ending at the full length, for each eta."""
    out = []
    full = lengths[-1]
    for k in (1, 2):
        for firsts in itertools.combinations(range(len(lengths) - 1), k):
            rungs = [*firsts, len(lengths) - 1]
            for eta in etas:
                survived = 0
                for d in dist:
                    best, alive = int(np.nanargmax(d[:, -1])), np.arange(d.shape[0])
                    for j in rungs[:-1]:
                        keep = alive[np.argsort(-d[alive, j], kind="stable")][:math.ceil(len(alive) / eta)]
                        alive = keep
                    survived += best in alive
                cost = sum(lengths[j] / eta ** n for n, j in enumerate(rungs))
                # were a promoted set continued from its last rung's end instead of simulated again
                went_on = sum((lengths[j] - (lengths[rungs[n - 1]] if n else 0.0)) / eta ** n
                              for n, j in enumerate(rungs))
                out.append({"rungs": [lengths[j] for j in rungs], "eta": eta, "best_survives": survived,
                            "sim_s_per_gait": cost, "saving": full / cost, "sim_s_per_gait_continued": went_on})
    return out


def spine(name: str, args: argparse.Namespace, pool: ProcessPoolExecutor) -> dict:
    morph = load_morphology(name)
    full = args.duration or morph.duration_s
    lengths = [*[float(x) for x in args.lengths.split(",") if float(x) < full], float(full)]
    options = dict(kv.split("=", 1) for kv in args.engine_option or [])
    options = {k: _value(v) for k, v in options.items()}
    cfg = TrialConfig(duration_s=full, engine=args.engine, dt_s=args.dt, settle_s=args.settle,
                      engine_options=options).to_dict()
    from spinefarm.robot.spaces import param_space

    n_dim = len(param_space(morph, args.controller))
    jobs = []
    for seed in range(args.seeds):
        rng = np.random.default_rng([seed, 46])
        for g in range(args.gaits):
            jobs.append(pool.submit(rung_distances_cm, name, args.controller, cfg, rng.random(n_dim).tolist(),
                                    g, lengths))
    dist = np.array([j.result() for j in jobs]).reshape(args.seeds, args.gaits, len(lengths))
    etas = [int(e) for e in args.etas.split(",")]
    table = rung_table(dist, lengths, etas)
    all_ladders = ladders(dist, lengths, etas)
    first_ok = {k for k, v in table.items() if v["spearman_rho_median"] >= args.min_rho}
    fine = [lad for lad in all_ladders if lad["best_survives"] == args.seeds and f"{lad['rungs'][0]:g}" in first_ok]
    chosen = min(fine, key=lambda lad: lad["sim_s_per_gait"]) if fine else None
    return {"lengths_s": lengths, "config": cfg, "controller": args.controller, "rungs": table,
            "ladders": all_ladders, "chosen": chosen,
            "prefix_exact": _prefix_exact(name, args.controller, cfg, lengths),
            "full_distance_cm_median": float(np.nanmedian(dist[:, :, -1]))}


def _prefix_exact(name: str, controller: str | None, cfg: dict, lengths: list[float]) -> bool:
    """A rung's trial of its own length gives the distance read from the full trial's path, to the bit."""
    morph = load_morphology(name)
    from spinefarm.robot.spaces import param_space

    u = np.random.default_rng(7).random(len(param_space(morph, controller)))
    from_path = rung_distances_cm(name, controller, cfg, u.tolist(), 7, lengths[:1])[0]
    short = TrialConfig.from_dict({**cfg, "duration_s": lengths[0]})
    alone = simulate(morph, u, short, 7, controller=controller).result.distance_m * 100.0
    return bool(abs(alone - from_path) <= 1e-12 * max(1.0, abs(alone)))


def _value(text: str) -> object:
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--spines", default="tetraspine", help="'all' or names, comma-separated")
    ap.add_argument("--controller", default=None)
    ap.add_argument("--engine", default="mujoco")
    ap.add_argument("--dt", type=float, default=None)
    ap.add_argument("--engine-option", action="append", default=None, metavar="KEY=VALUE")
    ap.add_argument("--settle", type=float, default=1.0)
    ap.add_argument("--duration", type=float, default=None, help="the full length (default: the morphology's)")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--gaits", type=int, default=27, help="parameter sets per seed")
    ap.add_argument("--lengths", default="1,2,3,5,10", help="rung lengths in s below the full length")
    ap.add_argument("--etas", default="2,3,4")
    ap.add_argument("--min-rho", type=float, default=0.8, help="the first rung's least median Spearman rho")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    names = builtin_names() if args.spines == "all" else args.spines.split(",")
    t0 = time.time()
    with ProcessPoolExecutor(args.jobs) as pool:
        spines = {n: spine(n, args, pool) for n in names}
    print(json.dumps({"benchmark": "ladder", "seeds": args.seeds, "gaits": args.gaits, "spines": spines,
                      "wall_s": time.time() - t0}))


if __name__ == "__main__":
    main()
