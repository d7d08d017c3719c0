"""`spinefarm examples DIR`: the files the README's commands use, written where the user wants them.

The gait files (examples/gaits/ of the source tree, shipped in the wheel as spinefarm/examples/) and a robot
spec to start from (my_spine.yaml, the Tetraspine under a name of its own). Written under DIR as the README
names them, so `spinefarm examples examples` makes `examples/gaits/tetraspine.json` where a clone has it.
Existing files are never replaced without --overwrite.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from spinefarm.protocol.errors import ConfigError

SPEC_NAME = "my_spine.yaml"


def examples_dir() -> Path:
    """The packaged copy (a wheel carries it as spinefarm/examples), else the source tree's examples/."""
    package = Path(__file__).resolve().parents[1]
    packaged = package / "examples"
    return packaged if (packaged / "gaits").is_dir() else package.parent / "examples"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("examples", help="write the example gaits and a robot spec the README uses into a folder",
                       description="Write the shipped gait files (gaits/*.json, gaits/efficient/*.json, ...) and "
                                   f"a robot spec to start from ({SPEC_NAME}) into DIR.")
    p.add_argument("dir", type=Path, metavar="DIR", help="the folder to write into (made if missing)")
    p.add_argument("--overwrite", action="store_true", help="replace files of the same names in DIR")
    p.set_defaults(func=cmd_examples)


def planned(target: Path) -> dict[Path, bytes]:
    """{path under target: contents} of everything the command writes."""
    from spinefarm.cli.robot_commands import derived_spec
    from spinefarm.robot.morphology.registry import builtin_path

    source = examples_dir()
    if not (source / "gaits").is_dir():
        raise ConfigError("the example files are not installed", received=str(source),
                          expected="a spinefarm wheel or a clone (reinstall with `pip install .` from a clone)")
    out = {target / f.relative_to(source): f.read_bytes() for f in sorted((source / "gaits").rglob("*.json"))}
    spec = derived_spec("tetraspine", builtin_path("tetraspine").read_text(), "my-spine")
    out[target / SPEC_NAME] = spec.encode()
    return out


def cmd_examples(args: argparse.Namespace) -> int:
    target: Path = args.dir
    if target.exists() and not target.is_dir():
        raise ConfigError("DIR is a file, not a folder", received=str(target), expected="a folder (made if missing)")
    files = planned(target)
    taken = [p for p in files if p.exists()]
    if taken and not args.overwrite:
        raise ConfigError(f"{len(taken)} of the example files already exist in {target}", received=str(taken[0]),
                          expected="a folder without them, or --overwrite to replace them")
    try:
        for path, data in files.items():
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_name(path.name + ".tmp")
            tmp.write_bytes(data)
            tmp.replace(path)
    except PermissionError as exc:
        raise ConfigError("DIR cannot be written: no write permission", received=str(exc.filename or target),
                          expected="a writable folder") from exc
    gaits = sum(1 for p in files if p.suffix == ".json")
    print(f"wrote {gaits} gait files under {target / 'gaits'} and {target / SPEC_NAME}")
    print("try:")
    print(f"  spinefarm trial tetraspine --params {target / 'gaits' / 'tetraspine.json'}")
    print(f"  spinefarm check {target / SPEC_NAME}")
    return 0
