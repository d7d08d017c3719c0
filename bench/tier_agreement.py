"""Agreement between the tiers: do MuJoCo and Bullet rank gaits alike?

For each of the four paper spines, seeded random parameter sets (and optionally the best trials of a run
file) run on both engines, at each engine's default step and at a converged step. Per spine and pair of
tiers it reports the Spearman rank correlation of the distance, the median distance ratio (MuJoCo / Bullet,
over gaits that move at least 1 cm in Bullet; `_far`: over those that move 10 cm or more) and how many of
MuJoCo's top 10 are in Bullet's top 10. NTRT's published gaits are replayed on both engines with the ratio
to NTRT's own figures. Prints one JSON object.

    python bench/tier_agreement.py                  # >= 100 sets per spine, 10 s trials (hours on 2 cores)
    python bench/tier_agreement.py --quick          # 12 sets per spine, 3 s trials, no converged steps
    python bench/tier_agreement.py --spines all     # every built-in, not only the four paper spines
    python bench/tier_agreement.py --sets 40 --duration 5 --best-of tetraspine=runs/x.h5 --jobs 2
    python bench/tier_agreement.py --controller tetraspine=sidewinding --duration 5 --settle 1 \
        --best-of tetraspine=runs/tetraspine.h5      # the Tetraspine in the paper's 9-parameter space
    python bench/tier_agreement.py --spines octahedral-complex --sets 16 --duration 5 --no-replays \
        --mujoco-options '{"contact_geometry": "capsules"}'    # which model choices bring the tiers closer
"""

from __future__ import annotations

import argparse
import json
import math
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from spinefarm.worker.tools.calibrate import spearman  # the one rank correlation, shared with calibrate
from spinefarm.worker.tools.replay import PUBLISHED_DIR

SPINES = ("tetraspine", "tetrahedral-complex", "octahedral-complex", "ribbed")
# converged steps: Bullet is within ~1.5 % at 0.25 ms (docs/accuracy.md), MuJoCo well within 1 % at 0.5 ms
CONVERGED_DT_S = {"bullet": 2.5e-4, "mujoco": 5e-4}
NTRT = PUBLISHED_DIR  # NTRT's published parameter sets, shipped with the package
REPLAYS = {"octahedral-complex": "OctahedralComplex/paper-2014-06-07",
           "tetrahedral-complex": "TetrahedralComplex/paper-2014-06-07",
           "tetraspine-ntrt": "TetraSpine/paper-2014-06-07", "ribbed": "Ribbed/paper-2014-06-07"}
MOVING_M = 0.01
FAR_M = 0.1  # gaits that clearly move: the ratio over these alone, apart from those that barely do
_CACHE = None  # one SetupCache per pool process: set-up reused as a worker does


def _trial(args: tuple) -> dict:
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.worker.trial.setup import SetupCache
    from spinefarm.worker.trial.simulation import TrialConfig, simulate

    global _CACHE
    _CACHE = _CACHE or SetupCache(8)

    spine, unit, seed, engine, dt, duration, settle, extra, controller = args
    morph = load_morphology(spine)
    cfg = {"duration_s": duration, "engine": engine, "settle_s": settle, **extra}
    if dt is not None:
        cfg["dt_s"] = dt
    try:
        choose = TrialConfig(**cfg)
        from spinefarm.worker.trial.episode import choose_step

        choose_step(morph, choose)
    except Exception:  # a step the string network cannot take: the automatic one
        cfg["auto_dt"] = True
    t0 = time.process_time()
    r = simulate(morph, np.asarray(unit), TrialConfig(**cfg), seed, setup=_CACHE, controller=controller).result
    return {"distance_m": r.distance_m if r.ok else math.nan, "status": str(r.status), "dt_s": r.extras["dt_s"],
            "cpu_s": time.process_time() - t0}


def _replay(args: tuple) -> dict:
    from spinefarm.worker.tools.replay import replay

    spine, folder, engine = args
    rep = replay(NTRT / folder, spine, engine=engine)
    return {"ntrt_distance_cm": rep.result.ntrt_distance_cm, "status": str(rep.result.status),
            "ratio_to_ntrt": rep.ratio, "ntrt_reference_cm": rep.reference.distance_cm if rep.reference else None}


def agreement(bullet: np.ndarray, mujoco: np.ndarray, top: int = 10) -> dict:
    ok = np.isfinite(bullet) & np.isfinite(mujoco)
    moving = ok & (np.abs(bullet) >= MOVING_M)
    k = min(top, int(ok.sum()))
    idx = np.flatnonzero(ok)
    top_b = set(idx[np.argsort(-bullet[ok])[:k]])
    top_m = set(idx[np.argsort(-mujoco[ok])[:k]])
    far = ok & (np.abs(bullet) >= FAR_M)
    return {"n": int(ok.sum()), "spearman": spearman(bullet, mujoco),
            "median_distance_ratio": float(np.median(mujoco[moving] / bullet[moving])) if moving.any() else None,
            "n_far": int(far.sum()),
            "median_distance_ratio_far": float(np.median(mujoco[far] / bullet[far])) if far.any() else None,
            "top_overlap": len(top_b & top_m), "top_k": k,
            "failed": {"bullet": int((~np.isfinite(bullet)).sum()), "mujoco": int((~np.isfinite(mujoco)).sum())}}


def _best_sets(path: str, n: int, controller: str | None) -> list[tuple[tuple[float, ...], int]]:
    """The n best complete trials of a run file by objective, read with h5py alone so that run files of
    earlier schema versions serve too."""
    import h5py

    with h5py.File(path, "r") as f:
        stored = f.attrs.get("controller")
        stored = stored.decode() if isinstance(stored, bytes) else stored
        if controller and stored and stored != controller:
            raise SystemExit(f"{path} searched the {stored!r} space; expected {controller!r}")
        t = f["trials"]
        ok = np.flatnonzero(t["status"][:] == b"complete")
        best = ok[np.argsort(-t["objective"][:][ok], kind="stable")[:n]]
        return [(tuple(float(x) for x in t["params_unit"][i]), int(t["seed"][i])) for i in best]


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="12 sets per spine, 3 s trials, defaults only")
    ap.add_argument("--sets", type=int, default=None, help="random parameter sets per spine (default 100)")
    ap.add_argument("--duration", type=float, default=None, help="simulated seconds per trial (default 10)")
    ap.add_argument("--settle", type=float, default=0.0, help="settle phase before scoring (s)")
    ap.add_argument("--spines", default=",".join(SPINES),
                    help="comma-separated robots, or 'all': every built-in (`spinefarm morphologies`)")
    ap.add_argument("--no-converged", action="store_true", help="only each engine's default step")
    ap.add_argument("--no-replays", action="store_true")
    ap.add_argument("--best-of", action="append", default=[], metavar="SPINE=RUN.h5",
                    help="also the 10 best trials of this run file")
    ap.add_argument("--mujoco-options", default="{}", help="MuJoCo engine options (JSON), e.g. "
                    "'{\"contact_geometry\": \"capsules\"}'")
    ap.add_argument("--bullet-options", default="{}", help="Bullet engine options (JSON)")
    ap.add_argument("--mujoco-dt", type=float, default=None,
                    help="MuJoCo's step in the default tier (s; default: its default step), e.g. to test "
                         "contacts stiffer than its 1 ms step allows (solref_time_s >= 2 steps)")
    ap.add_argument("--mujoco-ground-friction", type=float, default=None,
                    help="ground friction of the MuJoCo runs (default: the morphology's)")
    ap.add_argument("--controller", action="append", default=[], metavar="SPINE=SPACE",
                    help="controller space of a spine (default: the morphology's first)")
    ap.add_argument("--no-screen", action="store_true", help="leave out the screen tier")
    ap.add_argument("--screen-dt", type=float, default=0.002)
    ap.add_argument("--screen-options", default='{"segment_contacts": "off"}')
    ap.add_argument("--jobs", type=int, default=2)
    return ap


def _tiers(args: argparse.Namespace) -> tuple[dict, dict]:
    """The tiers to run ({tier: {engine: step or None}}) and each one's trial settings (`options`)."""
    extra = {"bullet": {"engine_options": json.loads(args.bullet_options)},
             "mujoco": {"engine_options": json.loads(args.mujoco_options)}}
    if args.mujoco_ground_friction is not None:
        extra["mujoco"]["ground_friction"] = args.mujoco_ground_friction
    tiers = {"default": {"bullet": None, "mujoco": args.mujoco_dt}}
    if not (args.quick or args.no_converged):
        tiers["converged"] = dict(CONVERGED_DT_S)
    if not args.no_screen:
        tiers["screen"] = {"mujoco": args.screen_dt}
        extra["screen"] = {"engine_options": {**extra["mujoco"]["engine_options"], **json.loads(args.screen_options)},
                           **{k: v for k, v in extra["mujoco"].items() if k != "engine_options"}}
    return tiers, extra


def spines_of(text: str) -> list[str]:
    """The robots a --spines value names: 'all' is every built-in, with each one's shipped constants."""
    from spinefarm.robot.morphology.registry import builtin_names

    return builtin_names() if text == "all" else text.split(",")


def _jobs(args: argparse.Namespace, tiers: dict, extra: dict, sets: int, duration: float, controllers: dict,
          best_of: dict) -> list[tuple]:
    """One job per spine, tier, engine and parameter set: (spine, tier, engine, index, _trial's arguments)."""
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.worker.trial.simulation import random_unit_params

    jobs: list[tuple] = []
    for spine in spines_of(args.spines):
        morph = load_morphology(spine)
        controller = controllers.get(spine)
        cases = [(tuple(random_unit_params(morph, s, controller=controller)), s) for s in range(1, sets + 1)]
        if spine in best_of:
            cases += _best_sets(best_of[spine], 10, controller)
        for tier, steps in tiers.items():
            for engine, dt in steps.items():
                opts = extra["screen" if tier == "screen" else engine]
                jobs += [(spine, tier, engine, i, (spine, u, s, engine, dt, duration, args.settle, opts, controller))
                         for i, (u, s) in enumerate(cases)]
    return jobs


def _spine_figures(by_tier: dict, duration: float) -> dict:
    """One spine's figures from its rows ({tier: {engine: {index: row}}}): cost, step, agreements."""
    res: dict = {}
    dist = {}
    for tier, by_engine in by_tier.items():
        for engine, cases in by_engine.items():
            dist[tier, engine] = np.array([cases[i]["distance_m"] for i in sorted(cases)])
            res.setdefault("cpu_s_per_sim_s", {})[f"{engine}@{tier}"] = float(
                np.median([c["cpu_s"] for c in cases.values()]) / duration)
            res.setdefault("dt_s", {})[f"{engine}@{tier}"] = float(np.median([c["dt_s"] for c in cases.values()]))
    for tier in ("default", "converged"):
        if tier not in by_tier:
            continue
        res[f"mujoco_vs_bullet@{tier}"] = agreement(dist[tier, "bullet"], dist[tier, "mujoco"])
    if "converged" in by_tier:
        for name, ref, other in (("mujoco_default_vs_bullet_converged", "bullet", "mujoco"),
                                 ("bullet_default_vs_bullet_converged", "bullet", "bullet"),
                                 ("mujoco_default_vs_mujoco_converged", "mujoco", "mujoco")):
            res[name] = agreement(dist["converged", ref], dist["default", other])
        if "screen" in by_tier:
            res["mujoco_screen_vs_bullet_converged"] = agreement(dist["converged", "bullet"],
                                                                 dist["screen", "mujoco"])
    if "screen" in by_tier:
        res["mujoco_screen_vs_bullet_default"] = agreement(dist["default", "bullet"], dist["screen", "mujoco"])
    return res


def main() -> None:
    args = _parser().parse_args()
    tiers, extra = _tiers(args)
    sets = args.sets or (12 if args.quick else 100)
    duration = args.duration or (3.0 if args.quick else 10.0)
    controllers = dict(c.split("=", 1) for c in args.controller)
    best_of = dict(b.split("=", 1) for b in args.best_of)

    t0 = time.time()
    jobs = _jobs(args, tiers, extra, sets, duration, controllers, best_of)
    replays = [] if args.no_replays else [(s, f, e) for s, f in REPLAYS.items() if (NTRT / f).is_dir()
                                          for e in ("bullet", "mujoco")]
    with ProcessPoolExecutor(args.jobs) as pool:
        futures = [pool.submit(_trial, j[-1]) for j in jobs]
        rfutures = [pool.submit(_replay, r) for r in replays]
        rows = [f.result() for f in futures]
        rrows = [f.result() for f in rfutures]
    table: dict = {}
    for (spine, tier, engine, i, _), row in zip(jobs, rows, strict=True):
        table.setdefault(spine, {}).setdefault(tier, {}).setdefault(engine, {})[i] = row
    out: dict = {"benchmark": "tier_agreement", "sets_per_spine": sets, "duration_s": duration,
                 "settle_s": args.settle, "options": extra, "controllers": controllers,
                 "best_of": best_of, "spines": {spine: _spine_figures(by_tier, duration)
                                                for spine, by_tier in table.items()}}
    out["replays"] = [{"morphology": s, "folder": f, "engine": e, **r}
                      for (s, f, e), r in zip(replays, rrows, strict=True)]
    out["wall_s"] = time.time() - t0
    print(json.dumps(out, default=lambda v: None if isinstance(v, float) and not math.isfinite(v) else v))


if __name__ == "__main__":
    main()
