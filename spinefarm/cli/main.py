"""`spinefarm` console script: one sub-command per user task, registered by topic modules."""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from spinefarm.protocol.errors import SpinefarmError

# Each module exposes register(subparsers); a sub-command sets `func(args) -> int`.
COMMAND_MODULES = tuple(f"spinefarm.cli.{name}" for name in (
    "sim_commands", "morph_commands", "robot_commands", "service_commands", "router_command", "calibrate_command",
    "docs_command", "fit_command", "examples_command"))


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="spinefarm", description="Search for gaits of tensegrity spines: single trials, distributed searches, "
        "a dashboard of their results.",
        epilog="Documentation: `spinefarm docs` lists the topics, `spinefarm docs TOPIC` prints one; "
               "`spinefarm COMMAND --help` gives a command's options.")
    parser.add_argument("--version", action="version", version=f"spinefarm {software_version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name != name:
                raise
            continue
        module.register(sub)
    return parser


def software_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("spinefarm")
    except PackageNotFoundError:
        return "unknown (not installed)"


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except SpinefarmError as exc:
        print(f"spinefarm {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        # the reader went away (e.g. `| head`): stop quietly, as other shell tools do
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141
    except OSError as exc:  # a file that vanished or a disk that filled up after the checks
        where = f" {exc.filename}" if exc.filename else ""
        print(f"spinefarm {args.command}: error: {exc.strerror or exc}{where}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
