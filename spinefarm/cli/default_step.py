"""A robot whose engine's default step is above its string network's stable-step estimate (the hardware
Tetraspine's stiff strings at Bullet's 1 ms) runs at a stable step unless --dt says otherwise: `trial`,
`search`, `calibrate` and `accuracy` ask for the automatic step (TrialConfig.auto_dt: the safety factor times
the estimate) and print the step they take. Engine-free: the estimate is numpy over the structure."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterable
from typing import Any

from spinefarm.protocol.errors import ParameterError

AUTO = "auto"


def step_overrides(dt: str | None) -> dict[str, Any]:
    """TrialConfig fields of a typed --dt: seconds, 'auto', or nothing."""
    if dt is None:
        return {}
    if dt == AUTO:
        return {"auto_dt": True}
    try:
        return {"dt_s": float(dt)}
    except ValueError as exc:
        raise ParameterError("--dt is not a number", received=dt, expected="seconds (e.g. 0.0005) or 'auto'") \
            from exc


def unstable_defaults(morph: Any, engines: Iterable[str]) -> tuple[float, dict[str, float]]:
    """(the robot's stable-step estimate in s, {engine: its default step} for those above it)."""
    from spinefarm.robot.engines import engine_spec
    from spinefarm.worker.sim.stability import estimate_stable_step

    limit_s = estimate_stable_step(morph).dt_limit_s
    over = {e: engine_spec(e).default_dt_s for e in engines if engine_spec(e).default_dt_s > limit_s}
    return limit_s, over


def choose_stable_default(args: argparse.Namespace, morph: Any, engines: Iterable[str], *,
                          given: bool = False) -> bool:
    """With no --dt (`given`: a step from elsewhere, e.g. a stored trial's), set args.dt to 'auto' when an
    engine's default step is unstable for the robot, and say so with the step taken. Whether it did."""
    if given or getattr(args, "dt", None) is not None:
        return False
    from spinefarm.robot.trial_config import TrialConfig

    limit_s, over = unstable_defaults(morph, engines)
    if not over:
        return False
    args.dt = AUTO
    step_s = TrialConfig().dt_safety_factor * limit_s
    defaults = ", ".join(f"{e}'s {dt * 1e3:g} ms" for e, dt in over.items())
    print(f"step: {step_s * 1e3:.3g} ms for {morph.name} (the default step, {defaults}, is above its stable "
          f"limit of {limit_s * 1e3:.3g} ms; --dt sets another)", file=sys.stderr, flush=True)
    return True
