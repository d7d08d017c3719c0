"""Fit the screen to the judge where they disagree (`calibrate --fit-screen N`, `search --engine auto`).

When a robot's calibration fails the agreement bands, the judge records a few seeded random gaits
(judge_recording), MuJoCo's own contact constants (SCREEN_CONSTANTS, which leave the judge as it is)
are fitted to those recordings by `spinefarm fit`'s machinery (worker.fit.fitting.fit_constants), and the
calibration runs again with the fitted constants. The budget is stated (FitBudget) and printed; the result
keeps the fit's decision, the fitted constants and their profile hash, and the figures before and after. A
fitted screen that still fails leaves the search on the judge's engine, and says so.
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass
from typing import Any

from spinefarm.protocol.errors import bounded, check_fields, whole
from spinefarm.protocol.settings import JUDGE_ENGINE
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.profile import profile_hash
from spinefarm.worker.tools.calibrate import CalibrationSettings, cache_path, calibration, reference_step
from spinefarm.worker.tools.pool import Progress

# MuJoCo-only constants (robot.profile: "apply only in that engine"): fitting them moves the screen, never the
# judge, so the judge's figures before and after the fit are the same trials
SCREEN_CONSTANTS = ("mujoco.solref_time_s", "mujoco.solref_damping_ratio")
WINDOW_S = 0.2  # as `spinefarm fit`'s default (docs/fitting.md)
# the judge's samples every 10 ms: a recording at the judge's own 0.25 ms step, finer than MuJoCo's, sends
# MuJoCo's windows to the diverged error (86.5 cm against 0.09 cm every 1 or 10 ms, tetraspine-ntrt seed 1)
RECORD_EVERY_S = 0.01
AGREEMENT = ("spearman", "top_overlap", "top_k", "median_distance_ratio", "n_moving", "decision")


@dataclass(frozen=True)
class FitBudget:
    """recordings: seeded random gaits the judge records (seeds 1..n), each duration_s long; evaluations: the
    losses of one CMA-ES start (0: no fit). Then one calibration more, on the fitted screen."""

    evaluations: int = whole(40, 0, 100_000)
    recordings: int = whole(3, 1, 100)
    duration_s: float = bounded(2.0, 0.5, 60.0)

    def __post_init__(self) -> None:
        check_fields(self, "screen fit ")

    def describe(self) -> str:
        return (f"{self.recordings} judge recordings of {self.duration_s:g} s, {self.evaluations} losses, then one "
                "calibration more")


def _figures(result: dict[str, Any]) -> dict[str, Any]:
    return {k: result.get(k) for k in AGREEMENT}


def judge_recording(morph: Any, judge: Any, seed: int) -> Any:
    """A seeded random gait's trial in the judge, recorded every RECORD_EVERY_S, as a fit's recording."""
    import numpy as np

    from spinefarm.robot.spaces import param_space
    from spinefarm.worker.fit.readers import from_trajectory
    from spinefarm.worker.trial.simulation import random_unit_params, simulate

    unit = random_unit_params(morph, seed)
    out = simulate(morph, unit, judge, seed)
    space = param_space(morph, None)
    return from_trajectory(out.trajectory.arrays(), judge.to_dict(),
                           space.to_named(space.from_unit(np.asarray(unit))), f"judge seed {seed}", morph.name)


def fit_screen(source: str, settings: CalibrationSettings, budget: FitBudget,
               progress: Progress | None = None) -> dict[str, Any]:
    """Record the judge, fit SCREEN_CONSTANTS in MuJoCo to it: {constants, window_error_cm, profile, wall_s}."""
    from spinefarm.robot.profile import constant
    from spinefarm.robot.trial_config import TrialConfig
    from spinefarm.worker.fit.fitting import fit_constants
    from spinefarm.worker.fit.loss import prepare
    from spinefarm.worker.fit.search import Bound

    t0 = time.time()
    morph = load_morphology(source)
    profile = dict(settings.profile)
    ref_dt_s, _ = reference_step(source)
    judge = TrialConfig(engine=JUDGE_ENGINE, dt_s=ref_dt_s, settle_s=0.0, profile=profile,
                        duration_s=budget.duration_s, record_every_s=RECORD_EVERY_S)
    recordings = [prepare(f"judge seed {s}", judge_recording(morph, judge, s), WINDOW_S, WINDOW_S)
                  for s in range(1, budget.recordings + 1)]
    screen = TrialConfig(engine="mujoco", dt_s=settings.dt_s, auto_dt=settings.auto_dt, settle_s=0.0,
                         profile=profile)
    bounds = [Bound(n, constant(n)[0].low, constant(n)[0].high) for n in SCREEN_CONSTANTS]
    fit = fit_constants(morph, screen, recordings, [], bounds, restarts=1, evaluations=budget.evaluations,
                        seed=0, progress=progress)
    fitted = {n: float(f"{fit['constants'][n]['fitted']:.6g}") for n in SCREEN_CONSTANTS}
    return {"constants": fitted, "at_bound": [n for n in SCREEN_CONSTANTS if fit["constants"][n]["at_bound"]],
            "window_error_cm": fit["window_error_cm"], "profile": {**profile, **fitted},
            "wall_s": round(time.time() - t0, 1)}


def with_screen_fit(source: str, settings: CalibrationSettings, before: dict[str, Any], budget: FitBudget,
                    progress: Progress | None = None) -> dict[str, Any]:
    """The calibration to act on: `before` when it passes or no fit is allowed, else the calibration of the
    fitted screen with a "screen_fit" record (cached beside the unfitted calibration)."""
    if before["decision"] == "mujoco" or budget.evaluations == 0:
        return before
    path = cache_path(source, settings).with_suffix(f".screenfit-{budget.evaluations}-{budget.recordings}.json")
    if path.is_file():
        try:
            return json.loads(path.read_text())
        except (OSError, ValueError):
            pass  # a damaged entry is fitted again
    t0 = time.time()
    fit = fit_screen(source, settings, budget, progress)
    fitted_settings = dataclasses.replace(settings, profile=tuple(sorted(fit["profile"].items())))
    after, _ = calibration(source, fitted_settings, progress=progress)
    passes = after["decision"] == "mujoco"
    record = {"budget": {**dataclasses.asdict(budget), "said": budget.describe()}, "fitted": fit["constants"],
              "at_bound": fit["at_bound"], "profile": fit["profile"], "profile_hash": profile_hash(fit["profile"]),
              "window_error_cm": fit["window_error_cm"], "before": _figures(before), "after": _figures(after),
              "decision": "mujoco" if passes else JUDGE_ENGINE, "wall_s": round(time.time() - t0, 1)}
    record["summary"] = summary(record)
    result = {**after, "screen_fit": record}
    if not passes:  # the fitted screen's figures are kept in the record; the search runs on the judge's engine
        result = {**before, "screen_fit": record}
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(result))
    except OSError:
        pass  # uncached: the next search fits again
    return result


def summary(r: dict[str, Any]) -> str:
    """One line: what was fitted, within what budget, the agreement before and after, and what it decided."""
    def agree(f: dict[str, Any]) -> str:
        rho = "-" if f["spearman"] is None else f"{f['spearman']:.3f}"
        ratio = "-" if f["median_distance_ratio"] is None else f"{f['median_distance_ratio']:.3f}"
        return f"rho {rho}, top-{f['top_k']} overlap {f['top_overlap']}, ratio {ratio}"

    fitted = ", ".join(f"{n} {v:.4g}" for n, v in r["fitted"].items())
    w = r["window_error_cm"]
    verdict = ("the fitted screen agrees: mujoco screens with the fitted constants" if r["decision"] == "mujoco"
               else f"the fitted screen still disagrees: the judge's engine ({JUDGE_ENGINE}) runs the search")
    return (f"screen fitted to the judge ({r['budget']['said']}; {r['wall_s']:g} s): {fitted} (profile "
            f"{r['profile_hash']}), window error {w['before']:.3g} -> {w['after']:.3g} cm; before: "
            f"{agree(r['before'])}; after: {agree(r['after'])}; {verdict}")
