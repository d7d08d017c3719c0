"""The robot every simulating command takes first: a built-in name or a spec file, said one way everywhere."""

from __future__ import annotations

import argparse

ROBOT_HELP = "built-in name (e.g. tetraspine; `spinefarm morphologies` lists them) or a .yaml spec file"


def add_robot_argument(p: argparse.ArgumentParser, *, omit_with: str | None = None, more: str = "") -> None:
    """The positional `morphology`; `omit_with`: the flag that names the robot instead (it is then optional);
    `more`: other forms the command takes."""
    help_text = ROBOT_HELP + (f", {more}" if more else "") + (f"; omit with {omit_with}" if omit_with else "")
    if omit_with is None:
        p.add_argument("morphology", help=help_text)
    else:
        p.add_argument("morphology", nargs="?", default=None, help=help_text)
