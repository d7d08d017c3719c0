"""`spinefarm replay` (NTRT's published gaits) and `spinefarm render` (pictures of a structure)."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from spinefarm.cli import checks, render_motion
from spinefarm.cli.profile_argument import add_profile_argument, profile_from
from spinefarm.cli.recorded_trial import load_record, simulate_recorded
from spinefarm.cli.robot_argument import add_robot_argument
from spinefarm.cli.sim_commands import add_engine_argument
from spinefarm.protocol.errors import ConfigError
from spinefarm.robot.engines import DEFAULT_ENGINE
from spinefarm.robot.trial_config import MOTOR_MODEL_NAMES


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("replay", help="run NTRT's published parameters and compare with NTRT's figure",
                       description="Replay NTRT's published parameters for a robot (shipped with spinefarm: "
                                   "tetraspine-ntrt, tetrahedral-complex, octahedral-complex, ribbed) or a "
                                   "folder of NTRT .nnw files on the matching NTRT-era morphology with NTRT's "
                                   "motor at 1 ms, and print distance, speed and COT beside NTRT's own "
                                   "figure.")
    p.add_argument("path", metavar="ROBOT_OR_FOLDER",
                   help="a robot with published parameters (e.g. octahedral-complex) or a folder holding "
                        "logs/bestParameters-<suffix>_{node,edge}-<i>.nnw")
    p.add_argument("--morphology", default=None,
                   help="morphology to run (default: from the robot folder name in PATH)")
    p.add_argument("--duration", type=float, default=None, help="simulated seconds (default: NTRT's trial length)")
    p.add_argument("--suffix", default="default", help="parameter set name (NTRT's argv[1]; default 'default')")
    p.add_argument("--seeds", type=int, default=0,
                   help="also run N replays with the start pose jittered by 1e-6 cm and report "
                        "their spread")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--gait", metavar="OUT.json", default=None,
                   help="also write the parameter set as a `trial --params` file (NTRT's controller space, named "
                        "physical values): to run it under this model's defaults or start a search from it "
                        "(--enqueue)")
    p.add_argument("--motor-model", choices=MOTOR_MODEL_NAMES, default=None,
                   help="default: the motor of the NTRT code the morphology mirrors (ntrt2014; ntrt2026 for "
                        "tetraspine-ntrt2026, the model of NTRT's recorded runs)")
    add_engine_argument(p)
    add_profile_argument(p)
    p.set_defaults(func=cmd_replay)

    r = sub.add_parser("render", help="draw a gait: a PNG strip or a video (rods dark, strings coloured by tension)",
                       description="Draw a morphology from its initial pose, a recorded trajectory, a short "
                                   "simulation or a stored trial of a run (--run), as a strip of keyframes "
                                   "(--out) and/or a video (--video). Strings are coloured by tension: blue "
                                   "low, red high.")
    add_robot_argument(r, omit_with="--run")
    r.add_argument("--out", type=Path, default=None, help="PNG file to write")
    r.add_argument("--record", type=Path, default=None,
                   help="trajectory .npz to draw (as written by `spinefarm trial --record`); with --duration, "
                        "the simulated trajectory is saved to this file instead")
    r.add_argument("--frames", type=int, default=None,
                   help="number of keyframes in a strip (default 6 for a trajectory, 1 for the initial pose)")
    r.add_argument("--params", type=Path, default=None,
                   help="JSON parameter file (as for `spinefarm trial`), an NTRT .nnw folder or a robot with "
                        "published parameters (e.g. tetrahedral-complex); implies a simulation")
    r.add_argument("--duration", type=float, default=None, help="simulate this many seconds and draw them")
    r.add_argument("--random-seed", type=checks.seed, default=0,
                   help="seed of random parameters when --params is absent")
    r.add_argument("--motor-model", choices=MOTOR_MODEL_NAMES, default=None)
    add_engine_argument(r)
    render_motion.add_arguments(r)
    r.set_defaults(func=cmd_render)


# -- replay --------------------------------------------------------------------------------------
def _finite(v: Any) -> Any:
    return None if isinstance(v, float) and not math.isfinite(v) else v


def replay_summary(report: Any) -> dict[str, Any]:
    r = report.result
    ref = report.reference
    return {k: _finite(v) for k, v in {
        "morphology": report.morphology,
        "motor_model": report.motor_model,
        "scored_segment": report.scored_segment,
        "path": str(report.folder),
        "node_values": list(report.parameters.node),
        "n_edge_files": len(report.parameters.edges),
        "status": "diverged" if report.diverged else "complete",
        "reason": r.reason,
        "duration_s": report.duration_s,
        "sim_time_s": r.sim_time_s,
        "ntrt_distance_cm": r.ntrt_distance_cm,
        "speed_cm_s": report.speed_cm_s,
        "robot_distance_cm": r.distance_m * 100.0,
        "work_j": r.work_j,
        "cot": r.cot,
        "ntrt_reference_cm": ref.distance_cm if ref else None,
        "ntrt_reference_duration_s": ref.duration_s if ref else None,
        "ntrt_reference_source": ref.source if ref else None,
        "ratio": report.ratio,
        "wall_time_s": r.wall_time_s,
        "engine": r.extras.get("engine"),
        "dt_s": r.extras.get("dt_s"),
    }.items()}


def cmd_replay(args: argparse.Namespace) -> int:
    from spinefarm.worker.tools.replay import JITTER_CM, gait_file, parameter_folder, replay, replay_spread

    if not 0 <= args.seeds <= 100:
        raise ConfigError("--seeds out of range", received=args.seeds, expected="0 to 100 jittered replays")
    if args.gait is not None:
        checks.output_path("--gait", args.gait, (".json",))
    engine = args.engine or DEFAULT_ENGINE
    args.path = parameter_folder(args.path)
    profile = profile_from(args)
    report = replay(args.path, args.morphology, duration_s=args.duration, suffix=args.suffix, engine=engine,
                    profile=profile, motor_model=args.motor_model)
    if args.gait is not None:
        from spinefarm.storage.export import write_gait

        write_gait(args.gait, gait_file(report))
        print(f"wrote the parameter set to {args.gait} (`spinefarm trial --params {args.gait}`)", file=sys.stderr)
    s = replay_summary(report)
    if args.seeds:
        spread = replay_spread(args.path, args.morphology, args.seeds, duration_s=args.duration,
                               suffix=args.suffix, engine=engine, profile=profile,
                               motor_model=args.motor_model)
        d = np.array([r.result.ntrt_distance_cm for r in spread if not r.diverged])
        ratios = [r.ratio for r in spread if r.ratio is not None]
        s["spread"] = {"jitter_cm": JITTER_CM, "n": len(spread),
                       "diverged": sum(r.diverged for r in spread),
                       "ntrt_distance_cm": [r.result.ntrt_distance_cm for r in spread],
                       "median_cm": float(np.median(d)) if d.size else None,
                       "min_cm": float(d.min()) if d.size else None, "max_cm": float(d.max()) if d.size else None,
                       "median_ratio": float(np.median(ratios)) if ratios else None}
    if args.json:
        print(json.dumps(s))
        return 1 if report.diverged else 0
    print(f"replay of {s['path']} on {s['morphology']} ({s['n_edge_files']} edge files, node "
          f"{s['node_values'][0]:g}, {s['node_values'][1]:g}; NTRT motor {report.motor_model}, dt 1 ms, {engine})")
    if report.diverged:
        print(f"  DIVERGED: {report.result.reason}; the figures below are from the last sane state")
    print(f"  NTRT distance {s['ntrt_distance_cm']:9.2f} cm in {s['sim_time_s']:.2f} s "
          f"(segment {report.scored_segment}, NTRT's scored segment)")
    print(f"  speed         {s['speed_cm_s']:9.3f} cm/s")
    cot = s["cot"]
    print(f"  COT           {cot:9.3f}" if cot is not None else "  COT               n/a (no distance)")
    if s["ntrt_reference_cm"] is not None:
        ratio = "n/a (diverged)" if s["ratio"] is None else f"{s['ratio']:.3f}"
        print(f"  NTRT recorded {s['ntrt_reference_cm']:9.2f} cm in {s['ntrt_reference_duration_s']:g} s "
              f"({s['ntrt_reference_source']})")
        print(f"  ratio         {ratio}  (our speed / NTRT's)")
    else:
        print("  NTRT recorded no usable figure for this robot")
    if "spread" in s:
        sp = s["spread"]
        if sp["median_cm"] is None:
            print(f"  jittered      all {sp['n']} replays diverged")
        else:
            med = "" if sp["median_ratio"] is None else f", median ratio {sp['median_ratio']:.3f}"
            print(f"  jittered      {sp['n']} replays (start pose +- 1e-6 cm): median {sp['median_cm']:.2f} cm, "
                  f"range {sp['min_cm']:.2f} - {sp['max_cm']:.2f} cm{med}; {sp['diverged']} diverged")
    return 1 if report.diverged else 0


# -- render --------------------------------------------------------------------------------------
def cmd_render(args: argparse.Namespace) -> int:
    from spinefarm.robot.bodies import build_bodies
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.worker.tools.render import frames_from_record, initial_frame, render

    if render_motion.wants_motion(args):
        return render_motion.cmd_render_motion(args)
    if args.out is None or not args.morphology:
        raise ConfigError("nothing to draw", received=f"morphology {args.morphology!r}, --out {args.out}",
                          expected="a morphology and --out STRIP.png, or --video GAIT.mp4|GAIT.gif")
    checks.output_path("--out", args.out, (".png",))
    if args.record is not None and (args.duration is not None or args.params is not None):
        checks.output_path("--record", args.record, (".npz",))
    morph = load_morphology(args.morphology)
    if args.frames is not None and not 1 <= args.frames <= 24:
        raise ConfigError("--frames out of range", received=args.frames, expected="1 to 24 keyframes")
    n_bodies = morph.structure.n_segments
    n_strings = len(morph.structure.strings)
    simulate_now = args.duration is not None or args.params is not None
    if simulate_now:
        outcome, record = simulate_recorded(args, morph, lambda duration: max(0.01, duration / 200))
        if not outcome.result.ok:
            print(f"note: the trial ended early ({outcome.result.reason}); drawing what was recorded")
        frames = frames_from_record(record, args.frames or 6, n_bodies, n_strings)
    elif args.record is not None:
        frames = frames_from_record(load_record(args.record, morph.name), args.frames or 6, n_bodies, n_strings)
    else:
        if args.frames not in (None, 1):
            raise ConfigError("--frames needs a trajectory", received=args.frames,
                              expected="--record FILE.npz or --duration S (the initial pose is one frame)")
        frames = [initial_frame(build_bodies(morph.structure), n_strings)]
    out = render(morph, frames, args.out)
    print(f"{morph.name}: {len(frames)} frame(s) -> {out}")
    return 0
