"""`spinefarm fit ROBOT|FILE RECORDING... --engine E --fit NAME[=LO:HI],...`: fit named physical constants to
recorded motion by multiple shooting (worker.fit; docs/fitting.md) and write them as a profile."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from spinefarm.cli import checks
from spinefarm.cli.fit_workers import add_worker_arguments, losses_maker
from spinefarm.cli.profile_argument import add_profile_argument, profile_from
from spinefarm.cli.robot_argument import add_robot_argument
from spinefarm.cli.sim_commands import (
    add_engine_argument,
    add_engine_option_argument,
    json_finite,
    parse_engine_options,
)

WINDOW_S = 0.2  # docs/fitting.md: why this length


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("fit", help="fit physical constants (friction, strings, masses, contacts) to recorded motion",
                       description="Fit named physical constants of a robot's model to recordings (docs/recordings.md) "
                                   "by multiple shooting: many short windows, each simulated from the recorded state "
                                   "and driven by the recorded rest lengths; CMA-ES over the constants from a few "
                                   "starts. Writes the fitted constants as a profile (--profile FILE elsewhere).")
    add_robot_argument(p)
    p.add_argument("recordings", nargs="+", type=Path, metavar="RECORDING",
                   help="recordings to fit: spinefarm .npz, `trial --record` .npz, NTRT run folders, pose .csv")
    p.add_argument("--fit", required=True, metavar="NAME[=LO:HI],...",
                   help="the constants to fit (docs/fitting.md), each within LO:HI (default: its plausible range)")
    p.add_argument("--hold-out", nargs="+", type=Path, default=[], metavar="RECORDING",
                   help="recordings only reported, never fitted")
    add_engine_argument(p)
    add_engine_option_argument(p)
    add_profile_argument(p)
    p.add_argument("--window", type=float, default=WINDOW_S, help=f"window length in s (default {WINDOW_S})")
    p.add_argument("--stride", type=float, default=None, help="a window starts every S s (default: the window)")
    p.add_argument("--skip", type=float, default=0.0, help="leave the first S s of each recording out")
    p.add_argument("--restarts", type=int, default=3, help="CMA-ES starts (default 3), for the spread")
    p.add_argument("--evaluations", type=int, default=120, help="losses per start (default 120)")
    p.add_argument("--seed", type=checks.seed, default=0)
    p.add_argument("--jobs", type=int, default=1, help="processes computing a generation's losses (default 1)")
    add_worker_arguments(p)
    p.add_argument("--out", type=Path, default=None, help="write the profile here (.yaml)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_fit)


def cmd_fit(args: argparse.Namespace) -> int:
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.robot.trial_config import TrialConfig
    from spinefarm.worker.fit.fitting import fit_constants
    from spinefarm.worker.fit.loss import prepare
    from spinefarm.worker.fit.readers import read_recording
    from spinefarm.worker.fit.search import parse_fit
    from spinefarm.worker.fit.windows import driven_strings

    if args.out is not None:
        checks.output_path("--out", args.out, (".yaml", ".yml"))
    checks.at_least("--restarts", args.restarts, 1, "CMA-ES starts")
    checks.at_least("--evaluations", args.evaluations, 6, "losses per start")
    checks.at_least("--jobs", args.jobs, 1, "processes")
    bounds = parse_fit(args.fit)
    maker = losses_maker(args, bounds)
    morph = load_morphology(args.morphology)
    cfg = TrialConfig(engine=args.engine or "bullet", engine_options=parse_engine_options(args.engine_option),
                      profile=profile_from(args))
    stride = args.stride or args.window

    def prepared(paths: list[Path]) -> list:
        out = []
        for path in paths:
            rec = read_recording(path)
            rec.check_robot(morph.structure.n_segments, len(morph.structure.strings), morph.name,
                            driven_strings(morph))
            out.append(prepare(str(path), rec, args.window, stride, args.skip))
        return out

    fitted, held = prepared(args.recordings), prepared(args.hold_out)
    from spinefarm.cli.waiting import Waiting

    with Waiting("fit", "losses") as wait:
        result = fit_constants(morph, cfg, fitted, held, bounds, args.restarts, args.evaluations, args.seed, wait,
                               maker or args.jobs)
    result = {"robot": morph.name, "engine": cfg.engine, "window_s": args.window, "stride_s": stride, **result}
    if args.out is not None:
        write_profile(args.out, morph.name, result, " ".join(["spinefarm", *sys.argv[1:]]))
    if args.json:
        print(json.dumps(json_finite(result)))
    else:
        print(summary(result))
    return 0


def write_profile(path: Path, robot: str, result: dict[str, Any], command: str) -> None:
    import yaml

    bound = [n for n, c in result["constants"].items() if c["at_bound"]]
    warn = f" WARNING: {', '.join(bound)} at the bounds (docs/fitting.md)." if bound else ""
    doc = {"robot": robot, "description": f"fitted in {result['engine']}: {command}.{warn}",
           "constants": {k: float(f"{v:.6g}") for k, v in result["profile"].items()}}
    path.write_text(yaml.safe_dump(doc, sort_keys=False))


def summary(r: dict[str, Any]) -> str:
    lines = [f"fit of {r['robot']} in {r['engine']}: windows of {r['window_s']:g} s every {r['stride_s']:g} s, "
             f"{r['evaluations']} evaluations over {len(r['restarts'])} starts",
             f"  window error {r['window_error_cm']['before']:.4g} cm -> {r['window_error_cm']['after']:.4g} cm "
             "(fitted recordings)"]
    for name, rec in r["recordings"].items():
        b, a = rec["before"], rec["after"]
        lines.append(f"  {'held out' if rec['held_out'] else 'fitted  '} {name}: window error "
                     f"{b['window_error_cm']:.4g} -> {a['window_error_cm']:.4g} cm; distance "
                     f"{b['distance_cm']:.2f} -> {a['distance_cm']:.2f} cm (recorded {a['recorded_distance_cm']:.2f})")
    for name, c in r["constants"].items():
        lines.append(f"  {name:32s} {c['start']:.5g} -> {c['fitted']:.5g} (starts gave {c['min']:.5g} .. "
                     f"{c['max']:.5g}; bounds {c['low']:g} .. {c['high']:g})"
                     + ("  AT ITS BOUND: a model error the constant may not close" if c["at_bound"] else ""))
    return "\n".join(lines)

