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

Prints one JSON object. The reference is the screening tier's full-length distance. With --judge each gait also
runs its full length in the judge's engine and step (Bullet at 0.25 ms, protocol.settings, the same settle, no
engine options), and beside each key above stands its `_judge` twin ranked against that distance: per rung
`spearman_rho_judge_*` and `best_survives_judge` (the full screen length too, as a rung), per ladder
`best_survives_judge` (the judge's best gait survives every cut before the full length) and `chosen_judge`
(the same rule); `screen_judge_rho` is the full screen length's rho against the judge, per seed.

With --around GAIT.json (a gait file of the spine, e.g. examples/gaits/) the gaits are that gait's parameter set
moved uniformly by up to --spread of each parameter's range (clipped to it) instead of uniform random: a space
whose random gaits barely move ranks nothing worth ranking.
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

from spinefarm.protocol.params import ParamSpace
from spinefarm.protocol.settings import JUDGE_DT_S, JUDGE_ENGINE
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


def judge_distance_cm(name: str, controller: str | None, cfg: dict, u: list[float], seed: int) -> float:
    """The full-length distance (cm) of one gait in the judge's engine and step (cfg: the screen's)."""
    judge = TrialConfig.from_dict({**cfg, "engine": JUDGE_ENGINE, "dt_s": JUDGE_DT_S, "engine_options": {}})
    out = simulate(load_morphology(name), np.array(u), judge, seed, controller=controller, setup=_CACHE)
    return out.result.distance_m * 100.0


def rung_table(dist: np.ndarray, lengths: list[float], etas: list[int], ref: np.ndarray | None = None,
               suffix: str = "") -> dict:
    """dist (seeds, gaits, lengths), the last the full length; ref (seeds, gaits) ranks the rungs instead of it
    (the full length then is a rung too), its keys ending in `suffix`."""
    table = {}
    rungs = lengths if ref is not None else lengths[:-1]
    ref = dist[:, :, -1] if ref is None else ref
    for j, length in enumerate(rungs):
        pairs = list(zip(dist, ref, strict=True))
        rhos = [float(spearmanr(d[:, j], r).statistic) for d, r in pairs]
        surv = {str(eta): int(sum(_in_top(d[:, j], int(np.nanargmax(r)), eta) for d, r in pairs)) for eta in etas}
        table[f"{length:g}"] = {f"spearman_rho{suffix}_median": float(np.median(rhos)),
                                f"spearman_rho{suffix}_min": min(rhos), f"spearman_rho{suffix}": rhos,
                                f"best_survives{suffix}": surv}
    return table


def _in_top(values: np.ndarray, index: int, eta: int, among: np.ndarray | None = None) -> bool:
    among = np.arange(len(values)) if among is None else among
    keep = among[np.argsort(-values[among], kind="stable")][:math.ceil(len(among) / eta)]
    return index in keep


def ladders(dist: np.ndarray, lengths: list[float], etas: list[int], ref: np.ndarray | None = None) -> list[dict]:
    """Every ladder of up to three rungs ending at the full length, for each eta; with ref (seeds, gaits), also
    in how many seeds ref's best survives its cuts (`best_survives_judge`)."""
    out = []
    full = lengths[-1]
    for k in (1, 2):
        for firsts in itertools.combinations(range(len(lengths) - 1), k):
            rungs = [*firsts, len(lengths) - 1]
            for eta in etas:
                alive = [_survivors(d, rungs[:-1], eta) for d in dist]
                survived = sum(int(np.nanargmax(d[:, -1])) in a for d, a in zip(dist, alive, strict=True))
                cost = sum(lengths[j] / eta ** n for n, j in enumerate(rungs))
                # were a promoted set continued from its last rung's end instead of simulated again
                went_on = sum((lengths[j] - (lengths[rungs[n - 1]] if n else 0.0)) / eta ** n
                              for n, j in enumerate(rungs))
                out.append({"rungs": [lengths[j] for j in rungs], "eta": eta, "best_survives": survived,
                            "sim_s_per_gait": cost, "saving": full / cost, "sim_s_per_gait_continued": went_on})
                if ref is not None:
                    out[-1]["best_survives_judge"] = sum(int(np.nanargmax(r)) in a
                                                         for r, a in zip(ref, alive, strict=True))
    return out


def _survivors(d: np.ndarray, cuts: list[int], eta: int) -> np.ndarray:
    """The gaits (indices) left after cutting to the best 1/eta (ceil) at each rung of `cuts` in turn."""
    alive = np.arange(d.shape[0])
    for j in cuts:
        alive = alive[np.argsort(-d[alive, j], kind="stable")][:math.ceil(len(alive) / eta)]
    return alive


def choose(table: dict, all_ladders: list[dict], seeds: int, min_rho: float, suffix: str = "") -> dict | None:
    """The cheapest ladder whose (ref's) best survives in every seed among those whose first rung ranks with
    median rho >= min_rho."""
    first_ok = {k for k, v in table.items() if v[f"spearman_rho{suffix}_median"] >= min_rho}
    fine = [lad for lad in all_ladders
            if lad[f"best_survives{suffix}"] == seeds and f"{lad['rungs'][0]:g}" in first_ok]
    return min(fine, key=lambda lad: lad["sim_s_per_gait"]) if fine else None


def spine(name: str, args: argparse.Namespace, pool: ProcessPoolExecutor) -> dict:
    morph = load_morphology(name)
    full = args.duration or morph.duration_s
    lengths = [*[float(x) for x in args.lengths.split(",") if float(x) < full], float(full)]
    options = dict(kv.split("=", 1) for kv in args.engine_option or [])
    options = {k: _value(v) for k, v in options.items()}
    cfg = TrialConfig(duration_s=full, engine=args.engine, dt_s=args.dt, settle_s=args.settle,
                      engine_options=options).to_dict()
    from spinefarm.robot.spaces import param_space

    space = param_space(morph, args.controller)
    centre = None if args.around is None else _gait_unit(args.around, name, space)
    jobs, judged = [], []
    for seed in range(args.seeds):
        rng = np.random.default_rng([seed, 46])
        for g in range(args.gaits):
            u = rng.random(len(space)) if centre is None else centre + rng.uniform(-1, 1, len(space)) * args.spread
            u = np.clip(u, 0.0, 1.0).tolist()
            jobs.append(pool.submit(rung_distances_cm, name, args.controller, cfg, u, g, lengths))
            if args.judge:
                judged.append(pool.submit(judge_distance_cm, name, args.controller, cfg, u, g))
    dist = np.array([j.result() for j in jobs]).reshape(args.seeds, args.gaits, len(lengths))
    ref = np.array([j.result() for j in judged]).reshape(args.seeds, args.gaits) if args.judge else None
    etas = [int(e) for e in args.etas.split(",")]
    table = rung_table(dist, lengths, etas)
    all_ladders = ladders(dist, lengths, etas, ref)
    out = {"lengths_s": lengths, "config": cfg, "controller": args.controller, "rungs": table,
           "ladders": all_ladders, "chosen": choose(table, all_ladders, args.seeds, args.min_rho),
           "prefix_exact": _prefix_exact(name, args.controller, cfg, lengths),
           "full_distance_cm_median": float(np.nanmedian(dist[:, :, -1])),
           "full_distance_cm_range": [float(np.nanmin(dist[:, :, -1])), float(np.nanmax(dist[:, :, -1]))]}
    if ref is not None:
        against = rung_table(dist, lengths, etas, ref, "_judge")
        for k, v in against.items():
            table.setdefault(k, {}).update(v)
        out["chosen_judge"] = choose(table, all_ladders, args.seeds, args.min_rho, "_judge")
        out["screen_judge_rho"] = against[f"{lengths[-1]:g}"]["spearman_rho_judge"]
        out["judge_distance_cm_median"] = float(np.nanmedian(ref))
    return out


def _prefix_exact(name: str, controller: str | None, cfg: dict, lengths: list[float]) -> bool:
    """A rung's trial of its own length gives the distance read from the full trial's path, to the bit."""
    morph = load_morphology(name)
    from spinefarm.robot.spaces import param_space

    u = np.random.default_rng(7).random(len(param_space(morph, controller)))
    from_path = rung_distances_cm(name, controller, cfg, u.tolist(), 7, lengths[:1])[0]
    short = TrialConfig.from_dict({**cfg, "duration_s": lengths[0]})
    alone = simulate(morph, u, short, 7, controller=controller).result.distance_m * 100.0
    return bool(abs(alone - from_path) <= 1e-12 * max(1.0, abs(alone)))


def _gait_unit(path: str, name: str, space: ParamSpace) -> np.ndarray:
    """The unit-cube point of a gait file's parameter set (its robot must be `name`)."""
    with open(path) as f:
        gait = json.load(f)
    if gait.get("morphology") != name:
        raise SystemExit(f"--around {path}: a gait of {gait.get('morphology')!r} received, one of {name!r} expected")
    return space.to_unit(space.physical(gait["params"]))


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
    ap.add_argument("--around", default=None, metavar="GAIT.json",
                    help="sample gaits around this gait file's parameter set instead of uniformly")
    ap.add_argument("--spread", type=float, default=0.1, help="with --around: the largest move, share of a range")
    ap.add_argument("--judge", action="store_true",
                    help="also rank against each gait's full length in the judge's engine and step")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    names = builtin_names() if args.spines == "all" else args.spines.split(",")
    t0 = time.time()
    with ProcessPoolExecutor(args.jobs) as pool:
        spines = {n: spine(n, args, pool) for n in names}
    print(json.dumps({"benchmark": "ladder", "seeds": args.seeds, "gaits": args.gaits, "around": args.around,
                      "spread": args.spread if args.around else None, "spines": spines,
                      "wall_s": time.time() - t0}))


if __name__ == "__main__":
    main()
