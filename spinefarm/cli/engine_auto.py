"""`search --engine auto` (search's default): calibrate the tiers on the robot (or use the cached calibration,
worker.calibrate), then screen on MuJoCo with rungs when it ranks the robot's gaits as Bullet does, else run
on Bullet. `auto` is no engine: it is resolved here, before the run's trial config is made, and the choice
with its figures is stored in the run's settings (protocol.engine_choice.EngineChoice)."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from typing import Any

from spinefarm.cli.stop_signals import die_with_parent

AUTO = "auto"


def add_arguments(p: argparse.ArgumentParser) -> None:
    from spinefarm.cli.calibrate_command import add_calibration_arguments

    g = p.add_argument_group("--engine auto", "the calibration that picks the tier (spinefarm calibrate)")
    add_calibration_arguments(g, prefix="calibrate-")


def default_rungs(duration_s: float) -> str:
    """Successive halving over a sixth of the trial, a third and the whole of it (5,10,30 for 30 s: the ladder
    bench/ladder.py chose, docs/performance.md)."""
    return f"{duration_s / 6:g},{duration_s / 3:g},{duration_s:g}"


def wants_auto(args: argparse.Namespace) -> bool:
    return args.engine == AUTO or (args.engine is None and getattr(args, "engine_default", None) == AUTO)


def choose_engine(args: argparse.Namespace) -> Any:
    """Resolve --engine auto in place (args.engine, and args.rungs when screening on MuJoCo without rungs):
    the EngineChoice stored with the run, or None when the engine was given or nothing is simulated. A
    calibration that cannot run falls back to Bullet (the default engine) and says why."""
    from spinefarm.coordinator.problem import is_test_objective

    if not wants_auto(args) or args.resume or not args.morphology or is_test_objective(args.morphology):
        if args.engine == AUTO:
            args.engine = None
        return None
    from spinefarm.cli.calibrate_command import settings_from
    from spinefarm.protocol.engine_choice import EngineChoice
    from spinefarm.protocol.errors import SpinefarmError

    # checked here, so a bad --calibrate-* value is an error, not a fall back to Bullet
    settings = settings_from(args, "calibrate-", controller=args.controller,
                             jobs=max(1, min(2, getattr(args, "workers", 1) or 1)))
    print(f"engine auto: calibrating the tiers on {args.morphology} (cached after the first time) ...",
          file=sys.stderr)
    try:
        result, cached = calibrate_in_child(args.morphology, settings)
    except SpinefarmError as exc:  # e.g. a robot no default step can simulate: the run's own checks say it
        print(f"engine auto: the calibration could not run ({exc}); bullet", file=sys.stderr)
        args.engine = None
        return None
    args.engine = result["decision"]
    rungs = None
    if args.engine == "mujoco" and args.rungs is None:
        from spinefarm.robot.morphology.registry import load_morphology

        args.rungs = rungs = default_rungs(args.duration or load_morphology(args.morphology).duration_s)
    choice = EngineChoice.from_calibration(result, cached, rungs)
    print(choice.describe(), file=sys.stderr)
    return choice


def calibrate_in_child(morphology: str, settings: Any) -> tuple[dict[str, Any], bool]:
    """`spinefarm calibrate --json` in its own process: calibrating runs both simulators, and the search's own
    process (the coordinator) never loads one. (the calibration, whether it came from the cache)"""
    from spinefarm.protocol.errors import ConfigError

    cmd = [sys.executable, "-P", "-m", "spinefarm", "calibrate", morphology, "--json",
           "--gaits", str(settings.gaits), "--search-trials", str(settings.search_trials),
           "--bests", str(settings.bests), "--duration", repr(settings.duration_s),
           "--settle", repr(settings.settle_s), "--jobs", str(settings.jobs)]
    if settings.controller:
        cmd += ["--controller", settings.controller]
    r = subprocess.run(cmd, capture_output=True, text=True, stdin=subprocess.DEVNULL, preexec_fn=die_with_parent)
    if r.returncode != 0:
        lines = [ln for ln in r.stderr.strip().splitlines() if ln.strip()] or [f"exit code {r.returncode}"]
        raise ConfigError(f"spinefarm calibrate {morphology} failed: {lines[-1][:300]}")
    result = json.loads(r.stdout.strip().splitlines()[-1])
    return result, bool(result.pop("cached", False))
