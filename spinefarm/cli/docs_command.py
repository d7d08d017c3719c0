"""`spinefarm docs [TOPIC]`: the user documentation, shipped inside the package (works from a wheel)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from spinefarm.protocol.errors import ConfigError


def docs_dir() -> Path:
    """The packaged copy (a wheel carries it as spinefarm/docs), else the source tree's docs/."""
    package = Path(__file__).resolve().parents[1]
    packaged = package / "docs"
    if packaged.is_dir() and any(packaged.glob("*.md")):
        return packaged
    return package.parent / "docs"


def topics() -> dict[str, Path]:
    d = docs_dir()
    found = {p.stem: p for p in sorted(d.glob("*.md")) if p.stem.lower() != "readme"}
    readme = d / "README.md" if (d / "README.md").is_file() else d.parent / "README.md"
    if readme.is_file():
        found = {"overview": readme, **found}
    return found


def _title(path: Path) -> str:
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("#"):
            return line.lstrip("#").strip()
    return ""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("docs", help="read the documentation: `spinefarm docs` lists topics, "
                                    "`spinefarm docs TOPIC` prints one",
                       description="The user documentation as plain Markdown, from the installed package.")
    p.add_argument("topic", nargs="?", help="a topic from the list (e.g. overview, model, distributed, replay)")
    p.set_defaults(func=cmd_docs)


def cmd_docs(args: argparse.Namespace) -> int:
    found = topics()
    if not found:
        raise ConfigError("no documentation found in this installation", received=str(docs_dir()),
                          expected="the spinefarm/docs folder of the package")
    if args.topic is None:
        width = max(len(t) for t in found)
        print("spinefarm documentation; read one with `spinefarm docs TOPIC`:\n")
        for name, path in found.items():
            print(f"  {name:<{width}}  {_title(path)}")
        return 0
    if args.topic not in found:
        raise ConfigError("no such documentation topic", received=args.topic, expected=f"one of {', '.join(found)}")
    sys.stdout.write(found[args.topic].read_text(encoding="utf-8"))
    return 0
