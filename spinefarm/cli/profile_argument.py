"""`--profile FILE`, worded once for every simulating command (trial, search, replay, calibrate, accuracy, fit's
starting point): named physical constants over the robot (robot.profile, docs/fitting.md)."""

from __future__ import annotations

import argparse

from spinefarm.robot.profile import load_profile


def add_profile_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument("--profile", default=None, metavar="FILE|NAME",
                   help="a profile: YAML `constants: {NAME: value}` laid over the robot and engine (friction, "
                        "string stiffness and damping, motor limits, rod density, contact constants; "
                        "docs/fitting.md), e.g. what `spinefarm fit` wrote, or a built-in profile's name")


def profile_from(args: argparse.Namespace) -> dict[str, float]:
    """The --profile file's (or built-in's) checked constants, {} without one."""
    path = getattr(args, "profile", None)
    return {} if path is None else load_profile(path)
