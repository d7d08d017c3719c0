"""Is a good result real? Re-simulate a trial at a finer step (and optionally with a perturbed start
pose and friction) and check that its distance holds ("machine learning tends to exploit physics
engines", paper section V)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.profile import ground_friction
from spinefarm.worker.trial.simulation import TrialConfig, simulate


@dataclass(frozen=True)
class VerifySettings:
    """refine: the step is divided by this; tolerance: allowed relative change of the distance;
    perturb: also run with the start pose jittered by pose_jitter_cm and friction scaled by
    (1 + friction_change)."""

    refine: int = 4
    tolerance: float = 0.05
    perturb: bool = False
    pose_jitter_cm: float = 0.01
    friction_change: float = 0.1


@dataclass(frozen=True)
class Verification:
    holds: bool
    verdict: str  # "holds" or "not reproduced: ..."
    distance_m: float
    fine_distance_m: float
    fine_dt_s: float
    fine_status: str
    perturbed_distance_m: float | None
    relative_change: float
    tolerance: float

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def verification_configs(config: TrialConfig, settings: VerifySettings,
                         morph: Morphology) -> list[tuple[str, TrialConfig]]:
    """The re-simulations a verification needs, as (name, config) pairs."""
    fine = dataclasses.replace(config, dt_s=config.step_s / settings.refine, auto_dt=False)
    out = [("fine", fine)]
    if settings.perturb:
        friction = (config.ground_friction if config.ground_friction is not None
                    else ground_friction(morph, config.profile))
        out.append(("perturbed", dataclasses.replace(
            fine, pose_jitter_cm=settings.pose_jitter_cm, ground_friction=friction * (1 + settings.friction_change))))
    return out


def judge(distance_m: float, results: dict[str, Any], fine_dt_s: float, settings: VerifySettings) -> Verification:
    """Verdict from the original distance and the re-simulated results (name -> TrialResult)."""
    fine = results["fine"]
    pert = results.get("perturbed")
    changes = []
    reasons = []
    for name, r in (("finer step", fine), ("perturbed", pert)):
        if r is None:
            continue
        if not r.ok:
            reasons.append(f"{name} run {r.status}: {r.reason}")
            changes.append(math.inf)
            continue
        change = abs(r.distance_m - distance_m) / max(abs(distance_m), 1e-9)
        changes.append(change)
        if change > settings.tolerance:
            reasons.append(f"{name} run moved {r.distance_m:.4g} m against {distance_m:.4g} m "
                           f"({change:.1%} > {settings.tolerance:.0%})")
    worst = max(changes)
    return Verification(
        holds=not reasons, verdict="holds" if not reasons else "not reproduced: " + "; ".join(reasons),
        distance_m=distance_m, fine_distance_m=fine.distance_m, fine_dt_s=fine_dt_s, fine_status=str(fine.status),
        perturbed_distance_m=None if pert is None else pert.distance_m, relative_change=worst,
        tolerance=settings.tolerance)


def verify_trial(morphology: Morphology | str, params: np.ndarray, config: TrialConfig, seed: int,
                 distance_m: float, settings: VerifySettings | None = None, *,
                 controller: str | None = None) -> Verification:
    """Re-simulate in this process and judge (workers run the same configs on the coordinator's behalf)."""
    s = settings or VerifySettings()
    morph = load_morphology(morphology)
    runs = verification_configs(config, s, morph)
    results = {name: simulate(morph, params, cfg, seed, controller=controller).result for name, cfg in runs}
    return judge(distance_m, results, runs[0][1].dt_s, s)


def verify_in_engine(morphology: Morphology | str, params: np.ndarray, config: TrialConfig, seed: int,
                     distance_m: float, engine: str, dt_s: float, *, controller: str | None = None) -> Verification:
    """Re-simulate a screened result in the judge engine at its converged step. The judge's distance is
    the one that counts; the result fails only if the judge's run fails."""
    morph = load_morphology(morphology)
    judge_cfg = dataclasses.replace(config, engine=engine, engine_options={}, dt_s=dt_s, auto_dt=False)
    r = simulate(morph, params, judge_cfg, seed, controller=controller).result
    change = abs(r.distance_m - distance_m) / max(abs(distance_m), 1e-9) if r.ok else math.inf
    return Verification(
        holds=r.ok, verdict="holds" if r.ok else f"not reproduced: {engine} run {r.status}: {r.reason}",
        distance_m=distance_m, fine_distance_m=r.distance_m, fine_dt_s=dt_s, fine_status=str(r.status),
        perturbed_distance_m=None, relative_change=change, tolerance=math.inf)
