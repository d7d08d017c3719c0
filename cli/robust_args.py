"""The robust-scoring flags of `search` and `coordinator`: --episodes, --randomize, --robust."""

from __future__ import annotations

import argparse
from typing import Any

from spinefarm.protocol.robust import MAX_EPISODES, STATISTICS, RobustSpec, parse_randomize


def add_robust_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("robust scoring (stored with the run)")
    g.add_argument("--episodes", type=int, default=None, metavar="K",
                   help=f"run every parameter set in K randomised worlds (1..{MAX_EPISODES}), each seeded from "
                        "the trial's seed; every episode is stored")
    g.add_argument("--randomize", default=None, metavar="NAME=VALUE,...",
                   help="what each episode draws: friction=F (x(1+U(-F,F))), mass=M (rod density x(1+U(-M,M))), "
                        "start_jitter_cm=J, scene=flat|rough; e.g. friction=0.1,mass=0.05,start_jitter_cm=0.5")
    g.add_argument("--robust", default=None, choices=STATISTICS,
                   help="the objective over the episodes: mean (default), q25 (25th percentile) or min")


def robust_settings(args: argparse.Namespace) -> dict[str, Any] | None:
    """RobustSpec.to_dict() of the flags given, or None for a plain run; one-line ConfigErrors."""
    if args.episodes is None and args.randomize is None and args.robust is None:
        return None
    randomize = parse_randomize(args.randomize) if args.randomize is not None else {}
    spec = RobustSpec(episodes=args.episodes if args.episodes is not None else 1, randomize=randomize,
                      statistic=args.robust or "mean")
    return spec.to_dict()
