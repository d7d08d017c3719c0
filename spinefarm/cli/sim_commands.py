"""`spinefarm trial` (and the shared helpers for simulation commands)."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from spinefarm.cli import checks
from spinefarm.cli.default_step import choose_stable_default
from spinefarm.cli.profile_argument import add_profile_argument, profile_from
from spinefarm.cli.robot_argument import add_robot_argument
from spinefarm.protocol.errors import ParameterError
from spinefarm.robot.engines import DEFAULT_ENGINE
from spinefarm.robot.spaces import param_space
from spinefarm.robot.trial_config import MOTOR_MODEL_NAMES

if TYPE_CHECKING:
    from spinefarm.robot.morphology.model import Morphology
    from spinefarm.storage.schema import RunMeta
    from spinefarm.worker.tools.accuracy import ParamSet


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("trial", help="run one trial and print its metrics",
                       description="Run one trial of a morphology under CPG + impedance control.")
    add_robot_argument(p, omit_with="--run")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--random-seed", type=checks.seed, default=None,
                     help="draw the parameters uniformly from the unit cube with this seed")
    src.add_argument("--params", type=Path, default=None,
                     help="JSON file of named physical parameter values ({name: value} or "
                          "{\"controller\": ..., \"params\": {name: value}})")
    src.add_argument("--run", type=Path, default=None, metavar="RUN.h5",
                     help="re-run a trial of this run file (its robot, controller, parameters, seed, length, "
                          "settle and trial settings; the flags below override them), e.g. its best in "
                          "another engine or at a finer step")
    p.add_argument("--trial-id", type=int, default=None, help="with --run: which trial (default: the run's best)")
    p.add_argument("--duration", type=float, default=None, help="simulated seconds (default: the morphology's)")
    p.add_argument("--dt", default=None,
                   help="physics step in seconds (default: the engine's, 0.001 for Bullet; see docs/engines.md), "
                        "or 'auto' for half the string network's stable-step estimate")
    checks.add_cpg_step_argument(p)
    p.add_argument("--controller", default=None, help="controller space (e.g. ntrt, sidewinding)")
    p.add_argument("--motor-model", choices=MOTOR_MODEL_NAMES, default=None)
    p.add_argument("--seed", type=checks.seed, default=None, help="trial seed (default: the random seed or 0)")
    p.add_argument("--settle", type=float, default=None, metavar="S",
                   help="settle this long with the CPG at rest and score locomotion from there (default 0)")
    p.add_argument("--scene", default=None,
                   help="flat (default), slope, rough or obstacles, optionally with ,field=value pairs, e.g. "
                        "'rough,rough_amplitude_cm=3' or 'flat,collision_filter=neighbours' (see docs/model.md)")
    add_engine_argument(p)
    add_engine_option_argument(p)
    add_profile_argument(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--record", type=Path, default=None, help="save the trajectory to FILE.npz")
    p.add_argument("--record-every", type=float, default=0.01, help="recording interval in seconds")
    p.set_defaults(func=cmd_trial)

    a = sub.add_parser("accuracy", help="speed against error over steps, solver, CPG, contacts and scenes",
                       description="Run the same seeded trials over a sweep of settings against a converged "
                                   "reference; print a table, write JSON and a PNG plot.")
    add_robot_argument(a)
    a.add_argument("--quick", action="store_true", help="reduced sweep (5 s trials, 3 steps) in a few minutes")
    a.add_argument("--seeds", type=int, default=None, help="random parameter sets (default 3 quick, 5 full)")
    a.add_argument("--duration", type=float, default=None, help="simulated seconds per trial")
    a.add_argument("--run", type=Path, default=None, help="also test the best trial of this HDF5 run file")
    a.add_argument("--run-best", type=int, default=1, help="how many of the run's best trials (default 1)")
    a.add_argument("--controller", default=None)
    a.add_argument("--jobs", type=int, default=2, help="worker processes")
    add_engine_argument(a)
    add_profile_argument(a)
    a.add_argument("--out", type=Path, default=Path("accuracy"), help="output prefix for .json and .png")
    a.add_argument("--json", action="store_true",
                   help="print one JSON object (the table goes to standard error)")
    a.set_defaults(func=cmd_accuracy)


def add_engine_argument(p: argparse.ArgumentParser) -> None:
    from spinefarm.robot.engines import ENGINES, engine_names

    p.add_argument("--engine", choices=engine_names(), default=None,
                   help="physics engine (default bullet): "
                   + "; ".join(f"{name}: {spec.summary}" for name, spec in ENGINES.items()))


def add_engine_option_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument("--engine-option", action="append", default=None, metavar="KEY=VALUE",
                   help="a setting of the engine, e.g. segment_contacts=off (mujoco) or solver_iterations=20 "
                        "(bullet); repeatable; see docs/engines.md")


def trial_overrides(args: argparse.Namespace) -> dict[str, Any]:
    """TrialConfig overrides from the flags `trial`, `search` and `coordinator` share (--dt, --engine,
    --engine-option, --scene, --settle, --motor-model, --cpg-step, --profile; those a command lacks are skipped).
    TrialConfig validates the values."""
    from spinefarm.cli.default_step import step_overrides

    out: dict[str, Any] = step_overrides(getattr(args, "dt", None))
    for flag, field in (("motor_model", "motor_model"), ("engine", "engine"), ("settle", "settle_s"),
                        ("cpg_step", "cpg_step_s")):
        if getattr(args, flag, None) is not None:
            out[field] = getattr(args, flag)
    if getattr(args, "engine_option", None):
        out["engine_options"] = parse_engine_options(args.engine_option)
    if getattr(args, "scene", None) is not None:
        from spinefarm.robot.scene import parse_scene

        out["scene"] = parse_scene(args.scene)
    if getattr(args, "profile", None) is not None:
        out["profile"] = profile_from(args)
    return out


def parse_engine_options(items: list[str] | None) -> dict[str, Any]:
    """KEY=VALUE pairs; values are JSON when they parse as JSON (numbers, true/false, lists), else strings.
    The engine validates names and values when the trial is built."""
    import json

    out: dict[str, Any] = {}
    for item in items or []:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise ParameterError("--engine-option is not KEY=VALUE", received=item,
                                 expected="e.g. segment_contacts=off")
        try:
            value = json.loads(raw)
        except ValueError:
            value = raw
        out[key.strip()] = value
    return out


def say_if_compiling() -> None:
    """The first simulation after an install compiles the kernels (numba) for a while: say so."""
    from spinefarm.worker.tools.warmup import kernels_cached

    if not kernels_cached():
        print("compiling the simulation kernels (first run after installing; about a minute, then cached) ...",
              file=sys.stderr, flush=True)


def load_params_file(path: Path) -> tuple[dict[str, float], str | None]:
    """Named physical values (and an optional controller name) from a JSON file."""
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError as exc:
        raise ParameterError("parameter file not found", received=str(path), expected="an existing JSON file") from exc
    except (OSError, UnicodeDecodeError) as exc:  # a folder, no permission, a binary file
        why = exc.strerror if isinstance(exc, OSError) and exc.strerror else type(exc).__name__
        raise ParameterError(f"parameter file cannot be read as text ({why})", received=str(path),
                             expected="a UTF-8 JSON file of name: value") from exc
    except json.JSONDecodeError as exc:
        raise ParameterError(f"parameter file is not JSON (line {exc.lineno})", received=str(path),
                             expected="a JSON object of name: value") from exc
    if not isinstance(data, dict):
        raise ParameterError("parameter file is not a JSON object", received=type(data).__name__,
                             expected="{name: value} or {\"controller\": ..., \"params\": {...}}")
    controller = None
    if "params" in data and isinstance(data["params"], dict):
        controller = data.get("controller")
        data = data["params"]
    bad = {k: v for k, v in data.items() if isinstance(v, bool) or not isinstance(v, int | float)}
    if bad:
        raise ParameterError("parameter values must be numbers", received=bad, expected="name: number")
    return {k: float(v) for k, v in data.items()}, controller


def result_summary(result: Any, morph_name: str, controller: str | None) -> dict[str, Any]:
    d = result.to_dict()
    d["morphology"] = morph_name
    d["controller"] = controller
    d["distance_cm"] = result.distance_m * 100.0
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in d.items()}


def cmd_trial(args: argparse.Namespace) -> int:
    from spinefarm.protocol.environment import environment_record
    from spinefarm.worker.trial.simulation import simulate

    checks.trial_flags(args)
    if args.record is not None:
        checks.output_path("--record", args.record, (".npz",))
    if args.trial_id is not None and args.run is None:
        raise ParameterError("--trial-id needs --run", received=args.trial_id, expected="--run RUN.h5 --trial-id N")
    morph, controller, params, seed, base, stored_id = _trial_inputs(args)
    engine = args.engine or base.get("engine", DEFAULT_ENGINE)
    choose_stable_default(args, morph, [engine], given=base.get("auto_dt") or (
        "dt_s" in base and engine == base.get("engine", DEFAULT_ENGINE)))
    cfg = _trial_config(args, base, controller)
    say_if_compiling()
    outcome = simulate(morph, params, cfg, seed)
    r = outcome.result
    if args.record is not None and outcome.trajectory is not None:
        space = param_space(morph, controller)
        np.savez_compressed(args.record, **outcome.trajectory.arrays(), morphology=morph.name,
                            morphology_json=json.dumps(morph.to_dict()), params_json=json.dumps(
                                space.to_named(_physical(morph, params, controller))),
                            trial_config_json=json.dumps(cfg.to_dict()))
    summary = result_summary(r, morph.name, controller or morph.controllers[0])
    if args.run is not None:
        summary["rerun_of"] = {"run": str(args.run), "trial_id": stored_id}
    if args.json:
        print(json.dumps({**summary, "environment": environment_record()}))
    else:
        _print_trial(args, r, morph, cfg, stored_id)
    return 0 if r.ok else 1


def _trial_inputs(args: argparse.Namespace) -> tuple[Any, str | None, np.ndarray, int, dict[str, Any], int | None]:
    """(morphology, controller, unit parameters, seed, stored trial config, stored trial id) of what
    `trial` runs: a stored trial of --run, or a robot with --params or random parameters."""
    from spinefarm.cli.environment_notes import note_environment, recorded_environment
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.worker.trial.simulation import random_unit_params

    if args.run is not None:
        morphology, controller, params, seed, base, stored_id = _stored_trial(args.run, args.trial_id)
        if args.morphology is not None:
            raise ParameterError("--run names its own robot", received=args.morphology,
                                 expected="no morphology with --run")
        morph = load_morphology(morphology)
        controller = args.controller or controller
        seed = args.seed if args.seed is not None else seed
        note_environment(args.run, recorded_environment(args.run))
        return morph, controller, params, seed, base, stored_id
    if args.morphology is None and args.params is None:
        raise ParameterError("no robot to run", received="nothing",
                             expected="a morphology, a --params gait file naming one, or --run RUN.h5")
    controller = args.controller
    if args.params is not None:
        params, file_controller = load_params_file(args.params)
        controller = controller or file_controller
    if args.morphology is None:
        from spinefarm.cli.gait_robot import gait_robot

        args.morphology = gait_robot(args.params)
    morph = load_morphology(args.morphology)
    if args.params is None:
        rseed = 0 if args.random_seed is None else args.random_seed
        params = random_unit_params(morph, rseed, controller)
    seed = args.seed if args.seed is not None else (args.random_seed or 0)
    return morph, controller, params, seed, {}, None


def _trial_config(args: argparse.Namespace, base: dict[str, Any], controller: str | None) -> Any:
    """The TrialConfig: a stored trial's config (`base`, else the defaults) with the flags on top."""
    from spinefarm.worker.trial.simulation import TrialConfig

    overrides = trial_overrides(args)
    if "engine" in overrides and overrides["engine"] != base.get("engine", DEFAULT_ENGINE):
        base.pop("engine_options", None)  # the run's options belong to its own engine
        base.pop("dt_s", None)  # and so does its step: the new engine's default unless --dt says
    overrides = {**base, **overrides, "controller": controller}
    if args.duration is not None:
        overrides["duration_s"] = args.duration
    if args.record is not None:
        overrides["record_every_s"] = args.record_every
    return TrialConfig.from_dict(overrides)


def _print_trial(args: argparse.Namespace, r: Any, morph: Any, cfg: Any, stored_id: int | None) -> None:
    if args.run is not None:
        length = "the robot's trial length" if cfg.duration_s is None else f"{cfg.duration_s:g} s"
        print(f"trial {stored_id} of {args.run}: {length} after a {cfg.settle_s:g} s settle")
    print(f"{morph.name}: {r.status}{' (' + r.reason + ')' if r.reason else ''}")
    print(f"  distance      {r.distance_m * 100:9.2f} cm  (robot centre of mass, ground plane)")
    print(f"  NTRT distance {r.ntrt_distance_cm:9.2f} cm  (segment {morph.scored_segment})")
    print(f"  speed         {r.speed_cm_s:9.3f} cm/s")
    print(f"  work          {r.work_j:9.3f} J")
    print(f"  COT           {r.cot:9.3f}")
    print(f"  simulated     {r.sim_time_s:9.3f} s in {r.wall_time_s:.2f} s wall "
          f"({r.extras.get('engine')}, dt {r.extras.get('dt_s', 0) * 1e3:g} ms)")
    if args.record is not None:
        print(f"  trajectory -> {args.record}")


def _stored_trial(path: Path, trial_id: int | None
                  ) -> tuple[Any, str | None, np.ndarray, int, dict[str, Any], int]:
    """(morphology spec, controller, unit parameters, seed, trial config, trial id) of a run file's trial, or
    of its best; the config carries the trial's own length and settle (a rung's, in a multi-fidelity run)."""
    from spinefarm.storage.hdf5 import Hdf5Storage

    store = Hdf5Storage.open_read(path)
    try:
        meta = store.run_meta()
        if trial_id is None:
            best = store.reported_best(1)[0]   # the best the report names
            if not best:
                raise ParameterError("run file has no finished trial", received=str(path),
                                     expected="a run with results, or --trial-id")
            rec = best[0]
        else:
            rec = store.trial(trial_id)
    finally:
        store.close()
    if rec.status == "waiting":
        raise ParameterError("that trial was sampled but never run", received=rec.trial_id,
                             expected="a trial with a result")
    config = {k: v for k, v in meta.trial_config.items() if k not in ("record_every_s",)}
    if math.isfinite(rec.duration_s):
        config["duration_s"] = rec.duration_s
    if math.isfinite(rec.settle_s):
        config["settle_s"] = rec.settle_s
    if rec.engine:
        config["engine"] = rec.engine
    if math.isfinite(rec.dt_s):
        config["dt_s"] = rec.dt_s
    spec, params = meta.morphology_spec or meta.morphology, np.asarray(rec.params_unit)
    if meta.run.get("body"):  # a co-designed run: the trial's own body, and its gait's part of the vector
        from spinefarm.protocol.run import RunConfig
        from spinefarm.robot.codesign import BodySearch, body_of_trial

        values, params = body_of_trial(RunConfig.from_dict(meta.run), params)
        spec = BodySearch.from_dict(meta.run["body"]).body(values).to_dict()
    return spec, meta.controller, params, rec.seed, config, rec.trial_id


def _physical(morph: Morphology, params: np.ndarray | dict, controller: str | None) -> np.ndarray:
    return param_space(morph, controller).physical(params)


def _best_of_run(path: Path, n: int = 1) -> tuple[list[ParamSet], RunMeta]:
    from spinefarm.storage.hdf5 import Hdf5Storage
    from spinefarm.worker.tools.accuracy import ParamSet

    store = Hdf5Storage.open_read(path)
    try:
        best = store.best(n)
        meta = store.run_meta()
    finally:
        store.close()
    if not best:
        raise ParameterError("run file has no finished trial", received=str(path), expected="a run with results")
    return [ParamSet(f"best of {path.name} (trial {rec.trial_id})", tuple(rec.params_unit), rec.seed)
            for rec in best], meta


def cmd_accuracy(args: argparse.Namespace) -> int:
    from spinefarm.cli.waiting import Waiting
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.worker.tools.accuracy import format_table, plot, run_accuracy

    checks.at_least("--seeds", args.seeds, 1, "random parameter sets")
    checks.at_least("--jobs", args.jobs, 1, "worker processes")
    best, controller, base = None, args.controller, None
    if args.run is not None:
        if not 1 <= args.run_best <= 50:
            raise ParameterError("--run-best out of range", received=args.run_best, expected="1 to 50")
        best, meta = _best_of_run(args.run, args.run_best)
        controller = controller or meta.controller
        base = {k: v for k, v in meta.trial_config.items() if k not in ("duration_s", "dt_s", "record_every_s")}
    if args.engine is not None:
        if base is not None and base.get("engine", DEFAULT_ENGINE) != args.engine:
            base.pop("engine_options", None)  # the run's options belong to its own engine
        base = {**(base or {}), "engine": args.engine}
    if args.profile is not None:
        base = {**(base or {}), "profile": profile_from(args)}
    seeds = args.seeds if args.seeds is not None else (3 if args.quick else 5)
    if choose_stable_default(args, load_morphology(args.morphology), [(base or {}).get("engine", DEFAULT_ENGINE)]):
        base = {**(base or {}), "auto_dt": True}  # the settings that name no step; the steps swept stay as named
    with Waiting("accuracy", "trials") as wait:
        report = run_accuracy(args.morphology, quick=args.quick, seeds=seeds, duration_s=args.duration,
                              jobs=args.jobs, best=best, controller=controller, base=base,
                              progress=lambda m: print(m, file=sys.stderr, flush=True), counted=wait)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    json_path = args.out.with_suffix(".json")
    png_path = args.out.with_suffix(".png")
    slim = {**report, "table": [{k: v for k, v in r.items()} for r in report["table"]]}
    json_path.write_text(json.dumps(json_finite(slim), indent=1))
    plot(report, str(png_path))
    words = sys.stderr if args.json else sys.stdout  # with --json, standard output is the one JSON object
    print(format_table(report), file=words)
    print(f"wrote {json_path} and {png_path}", file=words)
    if args.json:
        print(json.dumps(json_finite(report)))
    return 0


def json_finite(x: Any) -> Any:
    """x with every non-finite float as None, so json.dumps writes standard JSON."""
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: json_finite(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [json_finite(v) for v in x]
    return x
