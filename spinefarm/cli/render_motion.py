"""`spinefarm render --video gait.mp4|gait.gif` and `spinefarm render --run RUN.h5`: a gait as a video (and/or
its strip of keyframes), from a stored trial, a recorded trajectory or a fresh simulation."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from spinefarm.cli import checks
from spinefarm.protocol.errors import ConfigError


def add_arguments(r: argparse.ArgumentParser) -> None:
    r.add_argument("--video", type=Path, default=None, metavar="GAIT.mp4|GAIT.gif",
                   help="write the gait as a video in real time (gif: always; mp4: with pip install "
                        "'spinefarm[video]' or an ffmpeg on PATH)")
    r.add_argument("--run", type=Path, default=None, metavar="RUN.h5",
                   help="draw a stored trial of this run file, re-simulated as the search ran it (its best, or "
                        "--trial-id); no morphology then")
    r.add_argument("--trial-id", type=int, default=None, help="with --run: which trial (default: the run's best)")


def wants_motion(args: argparse.Namespace) -> bool:
    return args.video is not None or args.run is not None


def _stored_motion(args: argparse.Namespace) -> tuple[dict[str, Any], Any]:
    from spinefarm.cli.sim_commands import _stored_trial
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.worker.tools.motion import simulate_motion

    if args.morphology:
        raise ConfigError("--run names its own robot", received=args.morphology, expected="no morphology with --run")
    spec, controller, params, seed, config, trial_id = _stored_trial(args.run, args.trial_id)
    job = {"morphology": spec, "controller": controller, "trial_config": config, "params_unit": list(params),
           "seed": seed, "title": f"{args.run.name} trial {trial_id}"}
    return simulate_motion(job), load_morphology(spec)


def _fresh_motion(args: argparse.Namespace, morph: Any) -> dict[str, Any]:
    from spinefarm.cli.recorded_trial import load_record, simulate_recorded
    from spinefarm.worker.tools.motion import motion_document, record_every_s

    if args.duration is None and args.params is None and args.record is not None:
        return motion_document(morph, load_record(args.record, morph.name), None, f"{morph.name}: {args.record}")
    outcome, record = simulate_recorded(args, morph, record_every_s)
    return motion_document(morph, record, outcome.result, morph.name)


def cmd_render_motion(args: argparse.Namespace) -> int:
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.worker.tools.motion import motion_record
    from spinefarm.worker.tools.render import frames_from_record, render
    from spinefarm.worker.tools.video import check_video_path, write_video

    if args.out is None and args.video is None:
        raise ConfigError("nothing to write", expected="--out STRIP.png and/or --video GAIT.mp4|GAIT.gif")
    if args.out is not None:
        checks.output_path("--out", args.out, (".png",))
    if args.video is not None:
        checks.output_path("--video", args.video, (".mp4", ".gif"))
        check_video_path(args.video)
    if args.frames is not None and not 1 <= args.frames <= 24:
        raise ConfigError("--frames out of range", received=args.frames, expected="1 to 24 keyframes")
    if args.run is None and not args.morphology:
        raise ConfigError("no robot to draw", expected="a morphology (e.g. tetraspine) or --run RUN.h5")
    if args.run is None and args.trial_id is not None:
        raise ConfigError("--trial-id needs --run", received=args.trial_id, expected="--run RUN.h5 --trial-id N")
    if args.run is not None:
        motion, morph = _stored_motion(args)
    else:
        morph = load_morphology(args.morphology)
        motion = _fresh_motion(args, morph)
    result = motion.get("result") or {}
    if result.get("reason"):
        print(f"note: the trial ended early ({result['reason']}); drawing what was recorded")
    if args.out is not None:
        frames = frames_from_record(motion_record(motion), args.frames or 6, motion["n_bodies"],
                                    len(motion["strings"]))
        print(f"{motion['morphology']}: {len(frames)} frame(s) -> {render(morph, frames, args.out)}")
    if args.video is not None:
        path, n = write_video(motion, args.video)
        print(f"{motion['morphology']}: {n} video frames, {motion['time_s'][-1]:.2f} s -> {path}")
    return 0
