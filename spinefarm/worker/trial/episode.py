"""The episode around the loop: the start pose, the physics step, the divergence guards and the
score. Engine-neutral: works on poses and string state, whatever engine produced them."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from spinefarm.protocol.errors import ConfigError
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.states import TrialStatus
from spinefarm.robot import fixedmath as fm
from spinefarm.robot.bodies import BodyModel, Quaternion, quaternion_matrix
from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.scene import GROUND_TOP_CM, SceneConfig, Terrain, surface_height_cm
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.sim import strings as sk
from spinefarm.worker.trial import scoring

if TYPE_CHECKING:
    from spinefarm.worker.sim.stability import StabilityEstimate

STRETCH_BASE_MIN_CM = 2.0


@lru_cache(maxsize=64)
def _stable_step(morph: Morphology, relocate: bool) -> StabilityEstimate:
    from spinefarm.worker.sim.stability import estimate_stable_step

    return estimate_stable_step(morph, relocate)


def choose_step(morph: Morphology, cfg: TrialConfig) -> float:
    """The physics step: dt_s, or the automatic choice; refuses a step known to be unstable."""
    est = _stable_step(morph, cfg.relocate_anchors)
    dt = cfg.step_s
    if cfg.auto_dt:
        return min(dt, cfg.dt_safety_factor * est.dt_limit_s)
    if cfg.refuse_unstable_dt and dt > est.dt_limit_s:
        raise ConfigError(
            f"dt_s is unstable for {morph.name}: its string network has omega_max = {est.omega_max_rad_s:.4g} rad/s "
            f"and gamma_max = {est.gamma_max_per_s:.4g} 1/s, so explicit string forces diverge above "
            f"dt = {est.dt_limit_s:.3g} s; set auto_dt (--dt auto) or a smaller step",
            received=dt, expected=f"dt_s <= {est.dt_limit_s:.3g} s")
    return dt


def _rotation_matrix(rotation: Quaternion | None) -> np.ndarray:
    return np.eye(3) if rotation is None else quaternion_matrix(rotation)


def start_rotation(scene: SceneConfig) -> Quaternion | None:
    """On a slope the robot starts lying on it: its build pose tilted like the plane."""
    if scene.kind != "slope" or scene.slope_deg == 0.0:
        return None
    a = math.radians(scene.slope_deg)
    return (math.sin(a / 2), 0.0, 0.0, math.cos(a / 2))


def build_poses(bodies: Sequence[BodyModel], lift_cm: float = 0.0, rotation: Quaternion | None = None) -> np.ndarray:
    """Start poses without jitter (tilted on a slope, lifted clear of the terrain)."""
    rot = _rotation_matrix(rotation)
    q = (0.0, 0.0, 0.0, 1.0) if rotation is None else rotation
    return np.array([[*(fm.matvec(rot, b.com_cm) + np.array([0.0, lift_cm, 0.0])), *q] for b in bodies])


def start_lift_cm(terrain: Terrain, morph: Morphology, rotation: Quaternion | None = None) -> float:
    """How far to raise the robot so that no point along its rods starts lower above the terrain
    than it would above flat ground (0 on flat ground)."""
    nodes = fm.rotate_rows(morph.structure.node_array(), _rotation_matrix(rotation))
    ends = np.array([(r.a, r.b) for r in morph.structure.rods])
    t = np.linspace(0.0, 1.0, 9)[:, None, None]
    pts = (nodes[ends[:, 0]][None] * (1 - t) + nodes[ends[:, 1]][None] * t).reshape(-1, 3)
    surface = surface_height_cm(terrain, pts[:, 0], pts[:, 2])
    return float(max(0.0, (surface - GROUND_TOP_CM).max()))


def check_state(poses: np.ndarray, last: np.ndarray, masses: np.ndarray, sstate: np.ndarray,
           start_length: np.ndarray, interval_s: float, cfg: TrialConfig, terrain: Terrain) -> str:
    """A divergence reason, or "" while the state is physically sane."""
    if not np.all(np.isfinite(poses)):
        return "diverged: non-finite pose"
    vel_m_s = (poses[:, :3] - last) / interval_s * scoring.CM
    speed = np.sqrt((vel_m_s**2).sum(axis=1))
    if speed.max() > cfg.max_body_speed_m_s:
        b = int(speed.argmax())
        return f"diverged: segment {b} speed {speed[b]:.3g} m/s exceeds {cfg.max_body_speed_m_s:g} m/s"
    kinetic = 0.5 * float((masses * speed**2).sum())
    if kinetic > cfg.max_kinetic_energy_j:
        return f"diverged: kinetic energy {kinetic:.3g} J exceeds {cfg.max_kinetic_energy_j:g} J"
    # heights count from the terrain under each segment (a slope or rough ground is not a divergence)
    surface = surface_height_cm(terrain, poses[:, 0], poses[:, 2])
    off_edge = ~np.isfinite(surface)
    surface = np.where(off_edge, GROUND_TOP_CM, surface)  # off the terrain's edge: ground level
    y_m = (poses[:, 1] - surface) * scoring.CM
    if y_m.min() < cfg.min_height_m or y_m.max() > cfg.max_height_m:
        b = int(np.argmax(np.maximum(cfg.min_height_m - y_m, y_m - cfg.max_height_m)))
        if off_edge[b] and y_m[b] < cfg.min_height_m:  # a fast gait walked off the ground, nothing diverged
            return (f"fell off the ground's edge: segment {b} at x {poses[b, 0]:.0f} cm, z {poses[b, 2]:.0f} cm, "
                    f"beyond the ground's half width of {cfg.scene.ground_half_extent_cm:g} cm (a larger one: "
                    f"--scene {cfg.scene.kind},ground_half_extent_cm=...)")
        return (f"diverged: segment {b} height {y_m[b]:.3g} m outside "
                f"[{cfg.min_height_m:g}, {cfg.max_height_m:g}] m")
    # very short strings (the ribbed spine's 0.3 cm muscles, 1.2 cm node to node) are judged against
    # STRETCH_BASE_MIN_CM, or they trip the guard in ordinary gaits
    ratio = sstate[:, sk.S_LPREV] / np.maximum(start_length, STRETCH_BASE_MIN_CM)
    if ratio.max() > cfg.max_stretch_ratio:
        i = int(ratio.argmax())
        return (f"diverged: string {i} stretched to {sstate[i, sk.S_LPREV]:.3g} cm, "
                f"{ratio[i]:.3g}x max(start length, {STRETCH_BASE_MIN_CM:g} cm) (limit {cfg.max_stretch_ratio:g}x)")
    return ""




@dataclass(frozen=True)
class EpisodeEnd:
    """How an episode ended, for its score (protocol.measured.Measured is the scored numbers): end_poses
    (nb, 7), steps_done (of locomotion) of dt_s each, work_internal (kg cm^2/s^2, of locomotion), reason ("" if it
    completed), start: the poses locomotion is scored from (the end of a settle phase; None: the build pose)."""

    end_poses: np.ndarray
    steps_done: int
    dt_s: float
    work_internal: float
    reason: str
    start: np.ndarray | None = None


def score(morph: Morphology, masses: np.ndarray, build: np.ndarray, measured: EpisodeEnd, seed: int,
          wall_time_s: float, extras: dict[str, float]) -> TrialResult:
    """A TrialResult from the start pose `build` (without jitter) and what was measured: the whole
    robot's COM distance, NTRT's scored-segment distance, speed, work and cost of transport.
    Locomotion counts from measured.start (default `build`); NTRT's distance always counts from `build`,
    as NTRT's did."""
    end_poses, reason, start = measured.end_poses, measured.reason, measured.start
    total_mass = float(masses.sum())
    sim_time = measured.steps_done * measured.dt_s
    start_com = scoring.robot_com_cm(build if start is None else start, masses)
    distance_cm = scoring.planar_distance_cm(start_com, scoring.robot_com_cm(end_poses, masses))
    seg = morph.scored_segment
    ntrt_cm = scoring.planar_distance_cm(build[seg, :3], end_poses[seg, :3])
    work_j = max(0.0, measured.work_internal) * scoring.WORK_J_PER_INTERNAL
    distance_m = distance_cm * scoring.CM
    return TrialResult(
        status=TrialStatus.FAILED if reason else TrialStatus.COMPLETE, reason=reason,
        distance_m=distance_m, ntrt_distance_cm=ntrt_cm,
        speed_cm_s=distance_cm / sim_time if sim_time > 0 else 0.0,
        work_j=work_j, cot=scoring.cost_of_transport(work_j, total_mass, distance_m),
        sim_time_s=sim_time, wall_time_s=wall_time_s, mass_kg=total_mass, seed=int(seed), extras=extras,
    )
