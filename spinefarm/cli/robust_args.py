"""The robust-scoring flags of `search` and `coordinator`: --episodes, --randomize, --robust."""

from __future__ import annotations

import argparse
from typing import Any

from spinefarm.protocol.errors import ConfigError
from spinefarm.protocol.robust import MAX_EPISODES, STATISTICS, RobustSpec, parse_randomize


def add_robust_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("robust scoring (stored with the run)")
    g.add_argument("--episodes", default=None, metavar="K|K,K,...",
                   help=f"run every parameter set in K randomised worlds (1..{MAX_EPISODES}), each seeded from "
                        "the trial's seed; every episode is stored. With --rungs, one K per rung (e.g. 2,8)")
    g.add_argument("--randomize", default=None, metavar="NAME=VALUE,...",
                   help="what each episode draws: friction=F (x(1+U(-F,F))), mass=M (rod density x(1+U(-M,M))), "
                        "start_jitter_cm=J, scene=flat|rough; e.g. friction=0.1,mass=0.05,start_jitter_cm=0.5")
    g.add_argument("--robust", default=None, choices=STATISTICS,
                   help="the objective over the episodes: mean (default), q25 (25th percentile) or min")


def robust_given(args: argparse.Namespace) -> bool:
    return any(getattr(args, k, None) is not None for k in ("episodes", "randomize", "robust"))


def robust_settings(args: argparse.Namespace, rung_durations_s: tuple[float, ...] | None = None
                    ) -> dict[str, Any] | None:
    """RobustSpec.to_dict() of the flags given, or None for a plain run; one-line ConfigErrors."""
    if not robust_given(args):
        return None
    randomize = parse_randomize(args.randomize) if args.randomize is not None else {}
    per_rung = _episodes(args.episodes)
    if len(per_rung) > 1 and len(per_rung) != len(rung_durations_s or ()):
        raise ConfigError("--episodes gives one K per rung", received=args.episodes,
                          expected=f"one K, or {len(rung_durations_s)} (one per --rungs duration)" if rung_durations_s
                          else "one K (a list needs --rungs)")
    rungs = dict(rung_episodes=per_rung, rung_durations_s=rung_durations_s) if len(per_rung) > 1 else {}
    spec = RobustSpec(episodes=per_rung[-1], randomize=randomize, statistic=args.robust or "mean", **rungs)
    return spec.to_dict()


def _episodes(text: str | None) -> tuple[int, ...]:
    if text is None:
        return (1,)
    try:
        return tuple(int(x) for x in str(text).split(","))
    except ValueError:
        raise ConfigError("--episodes is not an integer (or one per rung)", received=text,
                          expected="K, e.g. 8, or K,K,... with --rungs, e.g. 2,8") from None
