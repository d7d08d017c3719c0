"""`spinefarm morphologies`, `spinefarm spec NAME` and `spinefarm check FILE.yaml`: the robots there are,
a built-in's spec file to start a new one from, and the morphology contract run on a user's file."""

from __future__ import annotations

import argparse
import json
import re
import sys

from spinefarm.cli.robot_argument import add_robot_argument
from spinefarm.protocol.errors import ConfigError
from spinefarm.robot.spaces import param_space


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("morphologies", help="list the built-in robots")
    p.add_argument("--json", action="store_true", help="print one JSON list")
    p.set_defaults(func=cmd_morphologies)

    p = sub.add_parser("spec", help="print a built-in's YAML spec file, to start a new robot from",
                       description="Print the spec file of a built-in morphology. Save it under a new name, "
                                   "change it, check it with `spinefarm check`, then search it.")
    p.add_argument("name", help="a built-in morphology (see `spinefarm morphologies`)")
    p.add_argument("--name", dest="new_name", default=None, metavar="NEW_NAME",
                   help="the new robot's name in the printed file (default my-<built-in>): runs, their ids and "
                        "the dashboard know it by this name, apart from the built-in's")
    p.add_argument("--search", action="store_true",
                   help="end the file with an example `search:` block (rod lengths, string stiffness and rod "
                        "density within +-30 %%) for a search over body and gait")
    p.set_defaults(func=cmd_spec)

    p = sub.add_parser("check", help="run the morphology contract on a spec file",
                       description="Checks that a robot builds; that its masses, inertias and start lengths "
                                   "are sane; that a passive settle (no CPG output) holds its shape; and that "
                                   "two runs agree. Exit 0 when every check passes, 1 otherwise.")
    add_robot_argument(p)
    p.add_argument("--engine", default="bullet", help="physics engine (default bullet)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_check)


def cmd_morphologies(args: argparse.Namespace) -> int:
    from spinefarm.robot.morphology.registry import builtin_names, load_morphology

    rows = []
    for name in builtin_names():
        m = load_morphology(name)
        rows.append({"name": name, "segments": m.structure.n_segments, "strings": len(m.structure.strings),
                     "controllers": list(m.controllers), "parameters": len(param_space(m)),
                     "description": m.description})
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    for r in rows:
        print(f"{r['name']:<22} {r['segments']:>2} segments {r['strings']:>4} strings  "
              f"{'/'.join(r['controllers']):<18} {r['description']}")
    return 0


NAME_LINE = re.compile(r"^name:.*$", re.MULTILINE)
ROBOT_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,47}$")


def derived_spec(builtin: str, text: str, new_name: str) -> str:
    """A built-in's spec file text under a name of its own (its first top-level `name:` line replaced)."""
    if not ROBOT_NAME.match(new_name):
        raise ConfigError("--name is not a robot name", received=new_name,
                          expected="letters, digits, '_', '.', '-' (at most 48, starting with a letter or digit)")
    if new_name == builtin:
        raise ConfigError("--name must differ from the built-in's", received=new_name,
                          expected=f"a name of its own, e.g. my-{builtin}")
    head = f"# derived from the built-in {builtin} (`spinefarm spec {builtin}`), under a name of its own\n"
    if NAME_LINE.search(text):
        return head + NAME_LINE.sub(f"name: {new_name}", text, count=1)
    return head + f"name: {new_name}\n" + text


def cmd_spec(args: argparse.Namespace) -> int:
    from spinefarm.robot.morphology.registry import builtin_path

    text = builtin_path(args.name).read_text()
    out = derived_spec(args.name, text, args.new_name or f"my-{args.name}")
    if args.search:
        out = out.rstrip("\n") + "\n\n" + example_search_block(args.name)
    sys.stdout.write(out)
    return 0


def example_search_block(builtin: str) -> str:
    """A `search:` block freeing rod lengths, each string tag's stiffness and each rod tag's density (so the
    segment mass) within +-30 % of the built-in's values."""
    from spinefarm.robot.morphology.registry import load_morphology

    s = load_morphology(builtin).structure
    lines = ["search:                       # body constants a search may change: [low, high] "
             "(docs/morphology-format.md)",
             "  segments.rod_length_scale: [0.7, 1.3]"]
    lines += [f"  string_materials.{t}.stiffness_n_per_m: [{0.7 * m.stiffness_n_per_m:.6g}, "
              f"{1.3 * m.stiffness_n_per_m:.6g}]" for t, m in s.string_materials]
    lines += [f"  rod_materials.{t}.density_kg_per_cm3: [{0.7 * m.density_kg_per_cm3:.6g}, "
              f"{1.3 * m.density_kg_per_cm3:.6g}]" for t, m in s.rod_materials]
    return "\n".join(lines) + "\n"


def _search_fields(source: str) -> tuple:
    """The search block of a spec file (checked as the robot loaded); built-ins have none."""
    from spinefarm.robot.morphology.specfile import load_search

    return load_search(source) if source.lower().endswith((".yaml", ".yml")) else ()


def cmd_check(args: argparse.Namespace) -> int:
    from spinefarm.cli.waiting import Waiting
    from spinefarm.robot.morphology.registry import load_ladder, load_morphology
    from spinefarm.worker.tools.contract import run_contract

    morph = load_morphology(args.morphology)
    body_fields = _search_fields(args.morphology)
    ladder = load_ladder(args.morphology)
    with Waiting(f"checking {morph.name}", "checks") as wait:
        results = run_contract(morph, args.engine, progress=wait)
    ok = all(r.passed for r in results)
    if args.json:
        print(json.dumps({"morphology": morph.name, "passed": ok,
                          "checks": [{"name": r.name, "passed": r.passed, "detail": r.detail} for r in results],
                          "search": [{"field": f.path, "low": f.low, "high": f.high, "unit": f.unit}
                                     for f in body_fields],
                          "ladder": {"rungs": ladder.rungs(morph.duration_s), "eta": ladder.eta,
                                     "reason": ladder.reason}}, indent=2))
    else:
        for f in body_fields:
            unit = "x the geometry as written" if f.unit == "1" else f.unit
            print(f"search {f.path}: {f.low:g} to {f.high:g} {unit}")
        print(f"ladder (a MuJoCo screen without --rungs): rungs {ladder.rungs(morph.duration_s)} eta {ladder.eta} "
              f"({ladder.reason})")
        for r in results:
            print(f"{'ok  ' if r.passed else 'FAIL'} {r.name}: {r.detail}")
        print(f"{morph.name}: {'every check passed' if ok else 'FAILED'}")
    return 0 if ok else 1
