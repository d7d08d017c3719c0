"""`search --engine auto` (search's default): calibrate the tiers on the robot against the judge (or use the
shipped or cached calibration, worker.tools.shipped_calibration and worker.tools.calibrate), then screen on MuJoCo with
rungs when it ranks the robot's gaits as Bullet does, else run on Bullet. `auto` is no engine: it is resolved
here, before the run's trial config is made, and the choice with its figures is stored in the run's settings
(protocol.engine_choice.EngineChoice)."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
from typing import Any

from spinefarm.worker.service.parent_death import HELPER_PREEXEC

AUTO = "auto"


def add_arguments(p: argparse.ArgumentParser) -> None:
    from spinefarm.cli.calibrate_command import add_calibration_arguments

    g = p.add_argument_group("--engine auto", "the calibration that picks the tier (spinefarm calibrate)")
    add_calibration_arguments(g, prefix="calibrate-")


def screen_ladder(args: argparse.Namespace, duration_s: float) -> tuple[str, int, str]:
    """The rungs, eta and reason `--engine auto` screens with when no `--rungs` are given: the robot's ladder
    (its spec's `ladder:` block, docs/performance.md's measured table for a built-in), else a sixth, a third
    and the whole trial at eta 4; a typed `--eta` wins."""
    from spinefarm.robot.morphology.registry import load_ladder

    ladder = load_ladder(args.morphology)
    if args.eta is not None:
        return ladder.rungs(duration_s), args.eta, f"{ladder.reason}; --eta {args.eta} given"
    return ladder.rungs(duration_s), ladder.eta, ladder.reason


def wants_auto(args: argparse.Namespace) -> bool:
    return args.engine == AUTO or (args.engine is None and getattr(args, "engine_default", None) == AUTO)


def choose_engine(args: argparse.Namespace) -> Any:
    """Resolve --engine auto in place (args.engine, and args.rungs and args.eta when screening on MuJoCo without
    rungs: screen_ladder):
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
    from spinefarm.worker.tools.screen_fit import FitBudget
    from spinefarm.worker.tools.shipped_calibration import shipped

    budget = FitBudget(evaluations=args.calibrate_fit_screen)  # a user's robot's screen is fitted within it
    from spinefarm.robot.morphology.registry import builtin_names

    # a built-in's failing screen is documented (docs/engines.md), not fitted by every search
    fit_evaluations = 0 if args.morphology in builtin_names() else budget.evaluations

    hit = shipped(args.morphology, settings)  # a built-in's, made for this model: no child
    result, cached = (None, False) if hit is None else ({**hit, "shipped": True}, True)
    if result is None:
        print(f"engine auto: calibrating the tiers on {args.morphology} against the judge (cached after the "
              "first time) ...", file=sys.stderr)
        try:
            result, cached = calibrate_in_child(args.morphology, settings, fit_evaluations,
                                                quiet=bool(getattr(args, "quiet", False)))
        except SpinefarmError as exc:  # e.g. a robot no default step can simulate: the run's own checks say it
            print(f"engine auto: the calibration could not run ({exc}); bullet", file=sys.stderr)
            args.engine = None
            return None
    args.engine = result["decision"]
    rungs, why = None, ""
    if args.engine == "mujoco" and args.rungs is None:
        from spinefarm.robot.morphology.registry import load_morphology

        duration_s = args.duration or load_morphology(args.morphology).duration_s
        rungs, args.eta, why = screen_ladder(args, duration_s)
        args.rungs = rungs
    choice = EngineChoice.from_calibration(result, cached, rungs, args.eta if rungs else None, why)
    print(choice.describe(), file=sys.stderr)
    return choice


def calibrate_in_child(morphology: str, settings: Any, fit_evaluations: int = 0, quiet: bool = False
                       ) -> tuple[dict[str, Any], bool]:
    """`spinefarm calibrate --json` in its own process: calibrating runs both simulators, and the search's own
    process (the coordinator) never loads one. Its progress lines pass through to this standard error (drawn
    for a terminal when this is one; none with `quiet`). Ended with the search: terminated on any exception (Ctrl-C's
    KeyboardInterrupt included), killed by the kernel if the search dies first; its pool ends with it
    (worker.tools.pool). (the calibration, whether it came from the cache)"""
    from spinefarm.cli.waiting import PROGRESS_ENV
    from spinefarm.protocol.errors import ConfigError

    cmd = [sys.executable, "-P", "-m", "spinefarm", "calibrate", morphology, "--json",
           "--gaits", str(settings.gaits), "--search-trials", str(settings.search_trials),
           "--bests", str(settings.bests), "--duration", repr(settings.duration_s),
           "--settle", repr(settings.settle_s), "--jobs", str(settings.jobs), "--fit-screen", str(fit_evaluations)]
    if settings.profile:  # the user's --profile, as the calibration's settings hold it
        cmd += ["--profile", _profile_file(dict(settings.profile))]
    if settings.controller:
        cmd += ["--controller", settings.controller]
    if settings.auto_dt or settings.dt_s is not None:
        cmd += ["--dt", "auto" if settings.auto_dt else repr(settings.dt_s)]
    env = {**os.environ, PROGRESS_ENV: "off" if quiet else "tty" if sys.stderr.isatty() else "lines"}
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, env=env,
                            preexec_fn=HELPER_PREEXEC)
    tail = bytearray()
    relay = threading.Thread(target=_relay, args=(proc.stderr, tail), name="calibration-stderr", daemon=True)
    relay.start()
    try:
        out = proc.stdout.read().decode(errors="replace")
        code = proc.wait()
        relay.join(timeout=5.0)
    except BaseException:
        _end(proc)
        raise
    if code != 0:
        lines = [ln for ln in tail.decode(errors="replace").splitlines() if ln.strip()] or [f"exit code {code}"]
        raise ConfigError(f"spinefarm calibrate {morphology} failed: {lines[-1].split(chr(13))[-1][:300]}")
    result = json.loads(out.strip().splitlines()[-1])
    return result, bool(result.pop("cached", False))


def screen_profile(choice: Any) -> dict[str, float]:
    """The constants a fitted screen adds to the run's profile (MuJoCo-only: the judge is unchanged), {} when
    the screen was not fitted or the search runs on the judge's engine."""
    fit = getattr(choice, "screen_fit", None)
    return dict(fit["fitted"]) if fit and choice.engine == "mujoco" else {}


def _profile_file(constants: dict[str, float]) -> str:
    """The constants as a profile file for the child (kept in the cache folder, named by their hash)."""
    import tempfile
    from pathlib import Path

    import yaml

    from spinefarm.protocol.errors import ConfigError
    from spinefarm.robot.profile import profile_hash
    from spinefarm.worker.tools.calibrate import cache_dir

    text = yaml.safe_dump({"constants": constants})
    for folder in (cache_dir() / "profiles", Path(tempfile.gettempdir())):  # a read-only cache: the temp folder
        path = folder / f"spinefarm-profile-{profile_hash(constants)}.yaml"
        try:
            folder.mkdir(parents=True, exist_ok=True)
            path.write_text(text)
            return str(path)
        except OSError:
            continue
    raise ConfigError("cannot write the calibration's profile file", received=str(cache_dir()),
                      expected="a writable SPINEFARM_CACHE_DIR or temp folder")


def _relay(stream: Any, tail: bytearray) -> None:
    """Copy the child's standard error to ours as it comes, keeping its last few kB for an error message."""
    out = getattr(sys.stderr, "buffer", None)
    while chunk := os.read(stream.fileno(), 4096):
        if out is not None:
            out.write(chunk)
            out.flush()
        else:  # a standard error without bytes (replaced by a test's capture)
            sys.stderr.write(chunk.decode(errors="replace"))
        tail.extend(chunk)
        del tail[:-4096]


def _end(proc: subprocess.Popen, grace_s: float = 3.0) -> None:
    """SIGTERM (its pool then gets SIGKILL from the kernel), SIGKILL after `grace_s`."""
    proc.terminate()
    try:
        proc.wait(timeout=grace_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
