"""Is a good result real? Re-simulate a trial at a finer step (and optionally with a perturbed start
pose and friction) and judge it as the search's judge does: "holds" within the robot's chaos floor, else
"moved X % at the finer step" ("machine learning tends to exploit physics engines", paper section V)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.states import Verification
from spinefarm.protocol.verdicts import judge_verdict, relative_change
from spinefarm.robot.chaos_floors import holds_tolerance
from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.profile import ground_friction
from spinefarm.worker.trial.simulation import TrialConfig, simulate


@dataclass(frozen=True)
class VerifySettings:
    """refine: the step is divided by this; tolerance: allowed relative change of the distance (None: the
    robot's chaos floor, as the search's judge uses); perturb: also run with the start pose jittered by
    pose_jitter_cm and friction scaled by (1 + friction_change)."""

    refine: int = 4
    tolerance: float | None = None
    perturb: bool = False
    pose_jitter_cm: float = 0.01
    friction_change: float = 0.1


@dataclass(frozen=True)
class VerifyReport:
    """A re-simulation's verdict (holds, moved, judged in another engine, diverged) and the reason in the
    search's words ("moved 3.0% at the finer step (...)"; empty when it holds)."""

    verdict: Verification
    reason: str
    distance_m: float
    fine_distance_m: float
    fine_dt_s: float
    fine_status: str
    perturbed_distance_m: float | None
    relative_change: float
    tolerance: float
    tolerance_source: str  # "given", "chaos floor of tetraspine 0.69%", "default chaos floor 5%"

    @property
    def holds(self) -> bool:
        return self.verdict == Verification.HOLDS

    def to_dict(self) -> dict[str, Any]:
        return {**dataclasses.asdict(self), "verdict": str(self.verdict), "holds": self.holds}


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


def judge(distance_m: float, results: dict[str, TrialResult], fine_dt_s: float,
          tolerance: tuple[float, str]) -> VerifyReport:
    """The search judge's verdict (protocol.verdicts) from the original distance and the re-simulated
    results (name -> TrialResult); `tolerance` is (relative tolerance, where it comes from)."""
    fine, pert = results["fine"], results.get("perturbed")
    judged = fine
    if pert is not None:  # the judge reads the perturbed run from the fine run's extras, as workers hand it
        judged = dataclasses.replace(fine, extras={**fine.extras, "perturbed_distance_m": pert.distance_m
                                                   if pert.ok else math.nan})
    verdict, reason = judge_verdict(distance_m, False, "finer-step", judged, tolerance[0])
    changes = [relative_change(r.distance_m, distance_m) if r.ok and math.isfinite(r.distance_m) else math.inf
               for r in (fine, pert) if r is not None]
    return VerifyReport(
        verdict=verdict, reason=reason, distance_m=distance_m, fine_distance_m=fine.distance_m,
        fine_dt_s=fine_dt_s, fine_status=str(fine.status),
        perturbed_distance_m=None if pert is None else pert.distance_m, relative_change=max(changes),
        tolerance=tolerance[0], tolerance_source=tolerance[1])


def verify_trial(morphology: Morphology | str, params: np.ndarray, config: TrialConfig, seed: int,
                 distance_m: float, settings: VerifySettings | None = None, *,
                 controller: str | None = None) -> VerifyReport:
    """Re-simulate in this process and judge as the search's judge does (workers run the same configs on
    the coordinator's behalf), within the robot's chaos floor unless a tolerance is given."""
    s = settings or VerifySettings()
    morph = load_morphology(morphology)
    runs = verification_configs(config, s, morph)
    results = {name: simulate(morph, params, cfg, seed, controller=controller).result for name, cfg in runs}
    return judge(distance_m, results, runs[0][1].dt_s, holds_tolerance(morph.name, morph.to_dict(), s.tolerance))
