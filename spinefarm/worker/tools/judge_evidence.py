"""Which engine moves as the recordings did? The evidence for choosing the judge (`bench/judge_evidence.py`).

Each engine restarts the recorded motion in short windows (multiple shooting, worker.fit.loss) at the same
converged step (the judge's, protocol.settings.JUDGE_DT_S) and with the robot's own constants; its window error
(RMS pose error, cm) is measured per recording. An engine is the closer one when its median window error is
below the other's by more than EVIDENCE_MARGIN and it is closer on most recordings; otherwise the evidence does
not decide and the judge stays JUDGE_ENGINE.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from spinefarm.protocol.settings import JUDGE_DT_S, JUDGE_ENGINE
from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.fit.loss import Prepared, window_error_cm

ENGINES = ("mujoco", "bullet")
# a median window error 20 % lower: above the spread of the held-out window errors over leave-one-out folds of
# NTRT's Tetraspine draws (docs/fitting.md: 0.08-0.14 cm in MuJoCo, 0.15-0.28 cm in Bullet)
EVIDENCE_MARGIN = 0.2


def judge_evidence(morph: Morphology, recordings: Sequence[Prepared], profile: dict[str, float] | None = None,
                   step_s: float = JUDGE_DT_S) -> dict[str, Any]:
    """{"window_error_cm": {engine: {recording: cm}}, "median_cm": {engine: cm}, "closer": engine or None,
    "judge": the engine the evidence names (JUDGE_ENGINE when it does not decide), "why": in words}."""
    base = TrialConfig(dt_s=step_s, profile=dict(profile or {}))
    errors = {e: {p.name: window_error_cm(morph, dataclasses.replace(base, engine=e), [p]) for p in recordings}
              for e in ENGINES}
    return {"step_s": step_s, "window_error_cm": errors, **decide(errors)}


def decide(errors: dict[str, dict[str, float]]) -> dict[str, Any]:
    """The closer engine by the rule of this module's docstring, from per-engine, per-recording window errors."""
    median = {e: float(np.median(list(v.values()))) for e, v in errors.items()}
    a, b = sorted(median, key=median.__getitem__)
    names = list(errors[a])
    wins = sum(errors[a][n] < errors[b][n] for n in names)
    closer = a if median[a] < (1 - EVIDENCE_MARGIN) * median[b] and 2 * wins > len(names) else None
    figures = (f"median window error {a} {median[a]:.4g} cm, {b} {median[b]:.4g} cm; {a} closer on {wins} of "
               f"{len(names)}")
    if closer is None:
        why = f"the recordings do not decide ({figures}): the judge stays {JUDGE_ENGINE}"
    else:
        why = f"{closer} moves closer to the recordings ({figures})"
    return {"median_cm": median, "closer": closer, "judge": closer or JUDGE_ENGINE, "why": why}
