"""`spinefarm calibrate ROBOT|FILE`: do the tiers rank this robot's gaits alike? (worker.tools.calibrate)"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from typing import TYPE_CHECKING

from spinefarm.cli.default_step import AUTO, choose_stable_default, step_overrides
from spinefarm.cli.profile_argument import add_profile_argument, profile_from
from spinefarm.cli.robot_argument import add_robot_argument

FIT_EVALUATIONS = 40  # search --engine auto's budget for fitting a user's robot's screen (docs/engines.md)

if TYPE_CHECKING:
    from spinefarm.worker.tools.calibrate import CalibrationSettings

# what `spinefarm calibrate --help` says first
DESCRIPTION = ("Run seeded random gaits plus the bests of a short search on MuJoCo and on the judge (Bullet at "
               "the judge's 0.25 ms step) and say whether a search may screen on MuJoCo (Spearman rho >= 0.9, "
               "top-10 overlap >= 8, median distance ratio in [0.9, 1.1]). The built-ins' results ship with "
               "the package; others are cached by the spec's hash (see --cache-dir; --refresh recomputes, "
               "--clear-cache empties it).")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("calibrate", help="compare the fast tier (MuJoCo) with Bullet on a robot's gaits",
                       description=DESCRIPTION)
    add_robot_argument(p, omit_with="--clear-cache")
    add_calibration_arguments(p)
    p.add_argument("--refresh", action="store_true", help="recompute even if a cached result exists")
    p.add_argument("--clear-cache", action="store_true", help="delete every cached calibration and exit")
    p.add_argument("--cache-dir", action="store_true", help="print where calibrations are cached and exit")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_calibrate)


def add_calibration_arguments(p: argparse.ArgumentParser, prefix: str = "") -> None:
    """The calibration's size; `search` takes them as --calibrate-gaits etc."""
    p.add_argument(f"--{prefix}gaits", type=int, default=40, help="seeded random gaits (default 40)")
    p.add_argument(f"--{prefix}search-trials", type=int, default=40,
                   help="trials of the short search on MuJoCo (a hill climb from the best random gait) whose "
                        "bests join (default 40)")
    p.add_argument(f"--{prefix}bests", type=int, default=10, help="how many of its bests (default 10)")
    p.add_argument(f"--{prefix}duration", type=float, default=5.0, help="simulated seconds per trial (default 5)")
    p.add_argument(f"--{prefix}settle", type=float, default=1.0, help="settle phase before scoring (default 1 s)")
    p.add_argument(f"--{prefix}fit-screen", type=int, default=FIT_EVALUATIONS if prefix else 0, metavar="N",
                   help="when the screen disagrees, fit MuJoCo's contact constants to recordings the judge makes "
                        f"(N losses; 0: no fit; default {FIT_EVALUATIONS if prefix else 0}) and calibrate again "
                        "(docs/engines.md)")
    if not prefix:
        p.add_argument("--controller", default=None, help="controller space (default: the robot's first)")
        p.add_argument("--jobs", type=int, default=2, help="processes (default 2)")
        add_profile_argument(p)
        p.add_argument("--dt", default=None, metavar="S|auto",
                       help="physics step of the screen (MuJoCo) in seconds, or 'auto' (half the string "
                            "network's stable-step estimate, at most its default); default: MuJoCo's default "
                            "step, or 'auto' for a robot a default is unstable for. The judge runs at its own "
                            "step (0.25 ms, or the automatic one where that is unstable)")


def settings_from(args: argparse.Namespace, prefix: str = "", controller: str | None = None, jobs: int = 1
                  ) -> CalibrationSettings:
    from spinefarm.worker.tools.calibrate import CalibrationSettings

    get = vars(args)
    key = prefix.replace("-", "_")
    # a search's own numeric --dt is its engine's step, not the calibration's; its 'auto' is both
    dt = get.get("dt") if not prefix or get.get("dt") == AUTO else None
    return CalibrationSettings(gaits=get[f"{key}gaits"], search_trials=get[f"{key}search_trials"],
                               bests=get[f"{key}bests"], duration_s=get[f"{key}duration"],
                               settle_s=get[f"{key}settle"], controller=get.get("controller", controller),
                               jobs=get.get("jobs", jobs), profile=tuple(profile_from(args).items()),
                               **step_overrides(dt))


def summary(result: dict, cached: bool) -> str:
    """The calibration as a few lines of text."""
    rho = result["spearman"]
    ratio = result["median_distance_ratio"]
    came = " [shipped]" if result.get("shipped") else " [cached]" if cached else ""
    lines = [f"calibration of {result['robot']} (spec {result['spec_hash']}){came}: "
             f"{result['n_random']} random gaits + {result['n_bests']} bests of a short search, "
             f"{result['settings']['duration_s']:g} s after a {result['settings']['settle_s']:g} s settle",
             f"  Spearman rho {'-' if rho is None else f'{rho:.3f}'}, top-{result['top_k']} overlap "
             f"{result['top_overlap']}, median distance ratio MuJoCo/Bullet "
             f"{'-' if ratio is None else f'{ratio:.3f}'} over {result['n_moving']} gaits that move"]
    for tier, t in result["tiers"].items():
        err = "-" if t["step_error"] is None else f"{100 * t['step_error']:.2f} %"
        step = f" at {1e3 * t['dt_s']:g} ms" if t.get("dt_s") else ""
        lines.append(f"  {tier:7s}{step} {t['cpu_s_per_sim_s']:.3f} CPU s per simulated s, step error {err}")
    lines.append(f"  decision: {result['decision']} ({result['reason']})")
    if result.get("screen_fit"):
        lines.append(f"  {result['screen_fit']['summary']}")
    return "\n".join(lines)


def cmd_calibrate(args: argparse.Namespace) -> int:
    from spinefarm.cli.waiting import Waiting
    from spinefarm.protocol.errors import ParameterError
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.worker.tools.calibrate import TIERS, cache_dir, cache_path, calibration, clean, trials_in
    from spinefarm.worker.tools.shipped_calibration import shipped

    if args.cache_dir:
        print(cache_dir())
        return 0
    if args.clear_cache:
        shutil.rmtree(cache_dir(), ignore_errors=True)
        print(f"cleared {cache_dir()}")
        return 0
    if not args.morphology:
        raise ParameterError("calibrate needs a robot", received="nothing",
                             expected="a built-in name (spinefarm morphologies) or a .yaml spec file")
    from spinefarm.worker.tools.screen_fit import FitBudget

    settings = settings_from(args)  # every value checked before the robot is loaded or a trial runs
    budget = FitBudget(evaluations=args.fit_screen)
    morph = load_morphology(args.morphology)
    if choose_stable_default(args, morph, TIERS):
        settings = settings_from(args)
    elif settings.dt_s is not None:  # a step every trial would refuse, refused before the first
        from spinefarm.robot.trial_config import TrialConfig
        from spinefarm.worker.trial.episode import choose_step

        choose_step(morph, TrialConfig(dt_s=settings.dt_s))
    with Waiting("calibration", "trials") as wait:
        if not args.json and (args.refresh or not (shipped(args.morphology, settings)
                                                   or cache_path(args.morphology, settings).is_file())):
            print(f"calibrating the tiers on {args.morphology}: up to {trials_in(settings)} trials on "
                  f"{settings.jobs} process{'es' if settings.jobs > 1 else ''} (cached after the first time)",
                  file=sys.stderr, flush=True)
        result, cached = calibration(args.morphology, settings, refresh=args.refresh, progress=wait)
        if budget.evaluations and result["decision"] != "mujoco":
            from spinefarm.worker.tools.screen_fit import with_screen_fit

            if not args.json:
                print(f"the screen disagrees: fitting it to the judge ({budget.describe()})", file=sys.stderr)
            result = with_screen_fit(args.morphology, settings, result, budget, progress=wait)
    print(json.dumps(clean({**result, "cached": cached})) if args.json else summary(result, cached))
    return 0
