"""A search's run, new or resumed, from what the user typed: checked before any file is written."""

from __future__ import annotations

import argparse
import re
import secrets
import socket
import sys
import time
from pathlib import Path
from typing import Any

from spinefarm.cli import checks
from spinefarm.cli.robust_args import robust_given, robust_settings
from spinefarm.protocol.errors import ConfigError, check_range


def free_port(host: str = "127.0.0.1") -> int:
    with socket.socket() as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def default_run_id(robot_name: str) -> str:
    """<robot name>-<time>-<random>: valid as a command-line value, a Zenoh key chunk and a file name."""
    stem = re.sub(r"[^A-Za-z0-9_.-]", "-", robot_name).lstrip("-_.")[:24] or "run"
    return f"{stem}-{time.strftime('%Y%m%d-%H%M%S')}-{secrets.token_hex(2)}"


def robot_name(morphology: str) -> str:
    """The name a run is known by: the robot's own name (a spec file's `name:`), never its path."""
    from spinefarm.coordinator.problem import is_test_objective

    if is_test_objective(morphology):
        return morphology.replace(":", "-")
    from spinefarm.robot.morphology.registry import load_morphology

    return load_morphology(morphology).name


def credentials(args: argparse.Namespace) -> Any:
    if not args.credentials:
        return None
    from spinefarm.protocol.credentials import load_credentials

    creds = load_credentials(args.credentials)
    if creds.world_readable:
        print(f"warning: credentials file {args.credentials} is readable by every user (chmod 600 it)",
              file=sys.stderr)
    return creds


def check_run_args(args: argparse.Namespace) -> None:
    """Everything typed that can be checked before a run file is created."""
    checks.endpoints("--listen", args.listen)
    checks.endpoints("--connect", args.connect)
    checks.port("--api-port", args.api_port, allow_off=True)
    if args.verify_tolerance is not None:
        check_range("--verify-tolerance", args.verify_tolerance, 0.0, 10.0, low_inclusive=False)
    check_range("--judge-drift", args.judge_drift, 0.0, 10.0, low_inclusive=False)
    check_range("--judge-share", args.judge_share, 0.0, 1.0, low_inclusive=False)
    checks.trial_flags(args)  # before an `--engine auto` calibration, as the trial config will
    search_flags(args)
    if args.out:
        checks.output_path("--out", args.out, (".h5", ".hdf5"))


def search_flags(args: argparse.Namespace) -> None:
    """The search's own number flags, each named with the range the run's settings hold it to."""
    for flag, attr, low in (("--trials", "trials", 1), ("--top-k", "top_k", 1), ("--startup-trials",
                            "startup_trials", 0), ("--workers", "workers", 0),
                            ("--eta", "eta", 2)):
        checks.at_least(flag, getattr(args, attr, None), low, "a whole number")
    checks.in_range("--batch", getattr(args, "batch", None), 1, 4096)  # a worker's own limit (zenoh_worker)
    checks.in_range("--sigma", getattr(args, "sigma", None), 0.0, 1.0, low_inclusive=False)
    checks.in_range("--lease", getattr(args, "lease", None), 0.0, low_inclusive=False)
    checks.in_range("--audit", getattr(args, "audit", None), 0.0, 1.0)
    checks.in_range("--audit-tolerance", getattr(args, "audit_tolerance", None), 0.0, 10.0)


def check_step(config: Any) -> None:
    """Refuse before the run starts a step every trial would refuse (e.g. tetraspine-hardware at 1 ms).
    Engine-free: the stable-step estimate is numpy over the structure."""
    if config.is_test_objective:
        return
    from spinefarm.robot.morphology.model import Morphology
    from spinefarm.robot.trial_config import TrialConfig
    from spinefarm.worker.sim.stability import estimate_stable_step

    cfg = TrialConfig.from_dict(config.trial_config)
    if cfg.auto_dt or not cfg.refuse_unstable_dt:
        return
    morph = Morphology.from_dict(config.morphology_spec)
    est = estimate_stable_step(morph, cfg.relocate_anchors)
    if cfg.step_s > est.dt_limit_s:
        raise ConfigError(
            f"dt_s is unstable for {morph.name}: its string network has omega_max = {est.omega_max_rad_s:.4g} rad/s "
            f"and gamma_max = {est.gamma_max_per_s:.4g} 1/s, so explicit string forces diverge above "
            f"dt = {est.dt_limit_s:.3g} s; set auto_dt (--dt auto) or a smaller step",
            received=cfg.step_s, expected=f"dt_s <= {est.dt_limit_s:.3g} s")


def open_run(args: argparse.Namespace) -> tuple[Any, Any, Path]:
    """(core, storage, run file) of the run the arguments ask for (--no-continue holds for this session only: it
    changes no result, only what is simulated again)."""
    core, storage, path = _open_run(args)
    core.ladder.continue_rungs = not getattr(args, "no_continue", False)
    return core, storage, path


def _open_run(args: argparse.Namespace) -> tuple[Any, Any, Path]:
    from spinefarm.cli.environment_notes import note_environment
    from spinefarm.coordinator.setup import new_run, resume_run

    trusted = bool(args.credentials)
    if args.resume:
        if args.morphology or args.out or robust_given(args) or args.enqueue:
            raise ConfigError("--resume continues a stored run (robust settings included)",
                              received="a morphology, --out, --enqueue or --episodes/--randomize/--robust too",
                              expected="only --resume RUN.h5")
        core, storage = resume_run(args.resume, trials_budget=args.trials, trusted_peers=trusted)
        note_environment(args.resume, storage.run_meta().environment or None)
        return core, storage, Path(args.resume)
    if not args.morphology:
        raise ConfigError("no morphology given", expected="a morphology name (e.g. tetraspine) or --resume")
    run_id = args.run_id or default_run_id(robot_name(args.morphology))
    config, settings = run_config(args, run_id)
    out = Path(args.out) if args.out else Path("runs") / f"{run_id}.h5"
    core, storage = new_run(config, settings, out, overwrite=args.overwrite, trusted_peers=trusted)
    return core, storage, out


def run_config(args: argparse.Namespace, run_id: str) -> tuple[Any, Any]:
    """The RunConfig and SearchSettings of a new run (--engine auto resolved first)."""
    from spinefarm.cli.engine_auto import choose_engine, screen_profile
    from spinefarm.cli.sim_commands import trial_overrides
    from spinefarm.coordinator.ladder.rungs import parse_rungs
    from spinefarm.coordinator.problem import build_run_config
    from spinefarm.protocol.settings import JudgePolicy

    given = None if args.rungs is None else parse_rungs(args.rungs)
    # typed mistakes fail before a calibration runs
    robust_settings(args, tuple(given) if given else None)
    units = enqueued(args)
    search_settings(args, given, 60.0 if args.lease is None else args.lease, JudgePolicy(), None, units)
    check_before_calibrating(args, run_id)
    choice = choose_engine(args)
    rungs = None if args.rungs is None else parse_rungs(args.rungs)
    if rungs:
        if args.duration is not None and args.duration != rungs[-1]:
            raise ConfigError("--duration and --rungs disagree on the trial length", received=args.duration,
                              expected=f"--rungs ending at the full length ({rungs[-1]:g} s) alone")
        args.duration = rungs[-1]
    overrides = trial_overrides(args)
    if fitted := screen_profile(choice):  # the screen's fitted constants travel with the run's trials
        overrides["profile"] = {**overrides.get("profile", {}), **fitted}
    config = build_run_config(run_id, args.morphology, objective=args.objective, seed=args.seed,
                              controller=args.controller, duration_s=args.duration,
                              trial_overrides=overrides,
                              robust=robust_settings(args, tuple(rungs) if rungs else None))
    check_step(config)
    lease = args.lease
    if lease is None:
        lease = max(60.0, 20.0 * float(config.trial_config.get("duration_s") or 0.0))
    return config, search_settings(args, rungs, lease, judge_policy(args, config), choice, units)


def check_before_calibrating(args: argparse.Namespace, run_id: str) -> None:
    """What the run config will check (objective, controller, step, scene, engine options, duration), checked
    before `--engine auto` calibrates for minutes; and a stable step for a robot whose default one is not."""
    from spinefarm.cli.default_step import choose_stable_default
    from spinefarm.cli.engine_auto import AUTO, wants_auto
    from spinefarm.cli.sim_commands import trial_overrides
    from spinefarm.coordinator.objectives import objective_fn
    from spinefarm.coordinator.problem import build_run_config, is_test_objective
    from spinefarm.robot.engines import DEFAULT_ENGINE
    from spinefarm.worker.tools.calibrate import TIERS

    objective_fn(args.objective)
    overrides = {k: v for k, v in trial_overrides(args).items() if not (k == "engine" and v == AUTO)}
    config = build_run_config(run_id, args.morphology, objective=args.objective, seed=args.seed,
                              controller=args.controller, duration_s=args.duration, trial_overrides=overrides)
    if args.dt is not None:
        check_step(config)  # a typed step every trial would refuse
    if not is_test_objective(args.morphology):
        from spinefarm.robot.morphology.registry import load_morphology

        engines = TIERS if wants_auto(args) else (overrides.get("engine", DEFAULT_ENGINE),)
        choose_stable_default(args, load_morphology(args.morphology), engines)


def enqueued(args: argparse.Namespace) -> tuple[tuple[float, ...], ...]:
    """--enqueue's parameter files as unit-cube vectors of the run's space (names, bounds and controller
    checked before anything runs)."""
    if not args.enqueue:
        return ()
    from spinefarm.cli.sim_commands import load_params_file
    from spinefarm.coordinator.problem import search_space

    space, controller = search_space(args.morphology, args.controller)
    units = []
    for path in args.enqueue:
        params, given = load_params_file(Path(path))
        if given is not None and given != controller:
            raise ConfigError(f"--enqueue {path} is a gait of another controller space", received=given,
                              expected=f"{controller} (the run's; --controller {given} searches that space)")
        units.append(tuple(space.to_unit(space.physical(params)).tolist()))
    return tuple(_with_file_body(args.morphology, u) for u in units)


def _with_file_body(morphology: str, unit: tuple[float, ...]) -> tuple[float, ...]:
    """In a co-designed run (a spec file with a `search:` block) an enqueued gait starts on the file's own body."""
    if not morphology.lower().endswith((".yaml", ".yml")):
        return unit
    import numpy as np

    from spinefarm.robot.codesign import BodySearch, with_file_body

    search = BodySearch.from_file(morphology)
    return unit if search is None else tuple(with_file_body(search, np.asarray(unit)).tolist())


def search_settings(args: argparse.Namespace, rungs: Any, lease_s: float, judge: Any, choice: Any,
                    enqueued: tuple[tuple[float, ...], ...] = ()) -> Any:
    """The SearchSettings the flags ask for (each value checked as it is built)."""
    from spinefarm.coordinator.samplers import DEFAULT_SAMPLER
    from spinefarm.coordinator.setup import SearchSettings
    from spinefarm.protocol.settings import DEFAULT_ETA, AuditPolicy

    return SearchSettings(trials=2000 if args.trials is None else args.trials,
                          sampler=args.sampler or DEFAULT_SAMPLER, sigma=args.sigma, top_k=args.top_k,
                          startup_trials=args.startup_trials, lease_s=lease_s, judge=judge,
                          audit=AuditPolicy(args.audit, args.audit_tolerance), rungs=rungs or None,
                          eta=DEFAULT_ETA if args.eta is None else args.eta, engine_choice=choice,
                          enqueued=enqueued)


def judge_policy(args: argparse.Namespace, config: Any) -> Any:
    """--verify-*: the judge's engine (bullet behind another screen engine) at --verify-dt, or the search's
    engine at a finer step."""
    from spinefarm.protocol.settings import JudgePolicy, Rung

    screen = config.trial_config.get("engine", "bullet")
    engine = args.verify_engine or ("bullet" if screen not in ("bullet", None) else None)
    rung = Rung(engine, args.verify_dt) if engine and engine != screen else Rung()
    return JudgePolicy(enabled=not args.no_verify, rung=rung, tolerance=args.verify_tolerance,
                       perturb=args.verify_perturb, drift=args.judge_drift,
                       share=args.judge_share,
                       # a test objective has a judge only when one is named, and then an opinion too
                       opinion=None if config.is_test_objective and rung.engine is None
                       else opinion_rung(args, rung.engine or screen or "bullet"))


def opinion_rung(args: argparse.Namespace, judge_engine: str) -> Any:
    """--opinion: the engine the judge does not run, at its converged step (None: no opinion). By default on
    when both engines are installed here (the workers announce theirs; one nobody runs is dropped at the end)."""
    import importlib.util

    from spinefarm.protocol.settings import OPINION_DT_S, Rung

    other = next((e for e in OPINION_DT_S if e != judge_engine), None)
    wanted = args.opinion
    if wanted is None:
        wanted = all(importlib.util.find_spec(m) is not None for m in ("pybullet", "mujoco"))
    return Rung(other, OPINION_DT_S[other]) if wanted and other is not None and not args.no_verify else None
