"""Leave-one-out: what a fit buys on motion it has not seen. Each recording in turn is held out, the constants
fitted to the others, and its window error reported before (the model's own values) and after."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.fit.fitting import LossesMaker, fit_constants
from spinefarm.worker.fit.loss import Prepared
from spinefarm.worker.fit.search import Bound


def leave_one_out(morph: Morphology, cfg: TrialConfig, recordings: Sequence[Prepared], bounds: Sequence[Bound],
                  restarts: int = 2, evaluations: int = 60, seed: int = 0,
                  jobs: int | LossesMaker = 1) -> dict[str, Any]:
    """{"folds": [{held_out, before, after, constants}], "window_error_before", "window_error_after"}: the
    held-out window errors (cm) per fold and their medians."""
    folds = []
    for i, held in enumerate(recordings):
        rest = [p for j, p in enumerate(recordings) if j != i]
        out = fit_constants(morph, cfg, rest, [held], bounds, restarts, evaluations, seed, jobs=jobs)
        figures = out["recordings"][held.name]
        folds.append({"held_out": held.name, "before": figures["before"]["window_error_cm"],
                      "after": figures["after"]["window_error_cm"],
                      "constants": {n: c["fitted"] for n, c in out["constants"].items()}})
    return {"folds": folds, "window_error_before": float(np.median([f["before"] for f in folds])),
            "window_error_after": float(np.median([f["after"] for f in folds]))}
