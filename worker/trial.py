"""The episode loop: build the scene, run CPG -> impedance -> motor -> strings -> engine, guard
against divergence, record, score. The only module that knows physics, control and scoring."""

from __future__ import annotations

import hashlib
import json
import math
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from functools import lru_cache

import numpy as np

from protocol.errors import ConfigError, ParameterError, check_range
from protocol.messages import TrialResult, TrialStatus
from worker import scoring
from worker.control.cpg import CpgIntegrator
from worker.morphology.model import Morphology
from worker.morphology.registry import load_morphology
from worker.morphology.structure import NEWTON
from worker.sim import strings as sk
from worker.sim.bodies import build_bodies, build_strings
from worker.sim.scene import GROUND_TOP_CM, SceneConfig, build_terrain, surface_height_cm

STRETCH_BASE_MIN_CM = 2.0
MOTOR_MODELS = {"physical": sk.MOTOR_PHYSICAL, "ntrt2014": sk.MOTOR_NTRT2014}


@dataclass(frozen=True)
class TrialConfig:
    """How to run one trial. None means "the morphology's default".

    motor_model: "physical" (limits in cm/s and cm/s^2, independent of dt) or "ntrt2014" (NTRT's
    per-step caps, only faithful at dt = 1 ms, for replaying published gaits).
    cpg_update_period_s: NTRT's controlTime (CPG output held in between).
    pose_jitter_cm: seeded Gaussian offset of every segment's start position (0: the seed is unused).
    auto_dt: use min(dt_s, dt_safety_factor * the string network's stable-step estimate).
    refuse_unstable_dt: raise ConfigError for a dt_s above that estimate (known to be unstable).
    """

    duration_s: float | None = None
    dt_s: float = 1e-3
    auto_dt: bool = False
    dt_safety_factor: float = 0.5
    refuse_unstable_dt: bool = True
    solver_iterations: int = 10
    friction_anchor: bool = True
    motor_model: str = "physical"
    controller: str | None = None
    cpg_update_period_s: float | None = None
    cpg_max_step_s: float = 1e-3
    relocate_anchors: bool = True
    pose_jitter_cm: float = 0.0
    ground_friction: float | None = None
    check_every_s: float = 0.01
    max_body_speed_m_s: float = 5.0
    min_height_m: float = -0.5
    max_height_m: float = 5.0
    max_stretch_ratio: float = 4.0
    max_kinetic_energy_j: float = 200.0
    record_every_s: float | None = None
    scene: SceneConfig = field(default_factory=SceneConfig)
    extras: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.duration_s is not None:
            check_range("duration_s", self.duration_s, 0.0, 3600.0, low_inclusive=False)
        check_range("dt_s", self.dt_s, 1e-6, 0.02)
        check_range("dt_safety_factor", self.dt_safety_factor, 0.0, 1.0, low_inclusive=False)
        if not isinstance(self.solver_iterations, int) or not 1 <= self.solver_iterations <= 1000:
            raise ConfigError("solver_iterations out of range", received=self.solver_iterations,
                              expected="an integer in [1, 1000]")
        if self.motor_model not in MOTOR_MODELS:
            raise ConfigError("unknown motor_model", received=self.motor_model, expected=sorted(MOTOR_MODELS))
        if self.cpg_update_period_s is not None:
            check_range("cpg_update_period_s", self.cpg_update_period_s, 1e-6, 10.0)
        check_range("cpg_max_step_s", self.cpg_max_step_s, 1e-6, 0.1)
        check_range("pose_jitter_cm", self.pose_jitter_cm, 0.0, 10.0)
        if self.ground_friction is not None:
            check_range("ground_friction", self.ground_friction, 0.0, 10.0)
        check_range("check_every_s", self.check_every_s, 1e-6, 10.0)
        check_range("max_body_speed_m_s", self.max_body_speed_m_s, 0.0, None, low_inclusive=False)
        check_range("max_stretch_ratio", self.max_stretch_ratio, 1.0, None, low_inclusive=False)
        check_range("max_kinetic_energy_j", self.max_kinetic_energy_j, 0.0, None, low_inclusive=False)
        if self.record_every_s is not None:
            check_range("record_every_s", self.record_every_s, 1e-6, 10.0)
        if isinstance(self.scene, Mapping):
            object.__setattr__(self, "scene", SceneConfig.from_dict(dict(self.scene)))
        if not isinstance(self.scene, SceneConfig):
            raise ConfigError("scene is not a scene config", received=type(self.scene).__name__,
                              expected="a SceneConfig or its dict")

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: Mapping) -> TrialConfig:
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ConfigError("unknown trial config fields", received=unknown, expected=sorted(known))
        return cls(**dict(d))

    def config_hash(self) -> str:
        blob = json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(blob.encode()).hexdigest()[:16]


@dataclass
class Trajectory:
    """Recorded at a chosen rate: time_s (n,), poses (n, n_bodies, 7) cm + quaternion,
    tension_n (n, n_strings), cpg_output_cm_s (n, n_nodes), rest_length_cm (n, n_strings)."""

    time_s: list[float] = field(default_factory=list)
    poses: list[np.ndarray] = field(default_factory=list)
    tension_n: list[np.ndarray] = field(default_factory=list)
    cpg_output_cm_s: list[np.ndarray] = field(default_factory=list)
    rest_length_cm: list[np.ndarray] = field(default_factory=list)

    def arrays(self) -> dict[str, np.ndarray]:
        return {"time_s": np.array(self.time_s), "poses": np.array(self.poses),
                "tension_n": np.array(self.tension_n), "cpg_output_cm_s": np.array(self.cpg_output_cm_s),
                "rest_length_cm": np.array(self.rest_length_cm)}


@dataclass
class TrialOutcome:
    result: TrialResult
    trajectory: Trajectory | None
    com_path_cm: np.ndarray  # (n_checks, 3) robot COM at every guard check, for path comparisons
    com_path_time_s: np.ndarray  # (n_checks,) the times of those checks


def resolve_params(morph: Morphology, params: np.ndarray | Mapping[str, float] | list,
                   controller: str | None) -> np.ndarray:
    """Physical parameter vector from a unit-cube vector or a mapping of named physical values."""
    space = morph.param_space(controller)
    if isinstance(params, Mapping):
        physical = space.from_named(params)
        space.to_unit(physical)  # bounds check with a named error
        return physical
    return space.from_unit(params)


def string_tables(morph: Morphology, start_length_cm: np.ndarray, node_of_string: dict[int, int]
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Packed per-string parameters (n, N_PARAM) and initial state (n, N_STATE) in internal units."""
    spec = morph.structure
    n = len(spec.strings)
    params = np.zeros((n, sk.N_PARAM))
    state = np.zeros((n, sk.N_STATE))
    for i, s in enumerate(spec.strings):
        mat = spec.string_material(s.tag)
        k = mat.stiffness_n_per_m
        params[i, sk.P_K] = k
        params[i, sk.P_B] = mat.damping_n_s_per_m
        params[i, sk.P_TMAX] = mat.max_tension_n * NEWTON
        params[i, sk.P_V] = mat.motor_speed_cm_s
        params[i, sk.P_A] = mat.motor_accel_cm_s2
        params[i, sk.P_LMIN] = mat.min_rest_length_cm
        params[i, sk.P_LACT] = mat.min_actuated_length_cm
        params[i, sk.P_NODE] = node_of_string.get(i, -1)
        gains = morph.control.gains(s.tag)
        if gains is not None:
            params[i, sk.P_MODE] = sk.MODE_IMPEDANCE
            params[i, sk.P_T0] = gains.tension_offset_n * NEWTON
            params[i, sk.P_KI] = gains.position_gain_n_per_m
            params[i, sk.P_BI] = gains.velocity_gain_n_s_per_m
            lc = gains.control_length_cm
            params[i, sk.P_LC] = start_length_cm[i] if lc is None else lc
        elif mat.drive_offset_cm is not None:
            params[i, sk.P_MODE] = sk.MODE_DRIVEN
            params[i, sk.P_DRIVE] = start_length_cm[i] - mat.drive_offset_cm
        rest = start_length_cm[i] - mat.pretension_n * NEWTON / k
        if rest <= 0:
            raise ConfigError(f"pretension of string {i} ({s.tag}) exceeds k * start length",
                              received=mat.pretension_n, expected=f"< {k * start_length_cm[i] / NEWTON:.3g} N")
        state[i, sk.S_REST] = rest
        state[i, sk.S_LPREV] = start_length_cm[i]
    return params, state


def simulate(morphology: Morphology | str | Mapping, params: np.ndarray | Mapping[str, float] | list,
             config: TrialConfig | None = None, seed: int = 0, *, controller: str | None = None,
             scene_factory=None) -> TrialOutcome:
    """Run one trial and return its result with the recorded trajectory (if config asks for one)."""
    t_wall = time.perf_counter()
    cfg = config or TrialConfig()
    morph = load_morphology(morphology)
    controller = controller or cfg.controller
    physical = resolve_params(morph, params, controller)
    network = morph.controller_space(controller).network(physical)
    if not isinstance(seed, int | np.integer):
        raise ParameterError("seed is not an integer", received=seed, expected="an integer")

    from worker.sim.physics import EngineSettings, PhysicsScene

    bodies = build_bodies(morph.structure)
    geom = build_strings(morph.structure, bodies, cfg.relocate_anchors)
    node_of_string = {int(s): n for n, s in enumerate(network.node_string)}
    sparams, sstate = string_tables(morph, geom.start_length_cm, node_of_string)
    masses = np.array([b.mass_kg for b in bodies])
    total_mass = float(masses.sum())
    rng = np.random.default_rng(seed)
    offsets = rng.normal(0.0, cfg.pose_jitter_cm, (len(bodies), 3)) if cfg.pose_jitter_cm > 0 else None

    dt = choose_step(morph, cfg)
    duration = cfg.duration_s or morph.duration_s
    n_steps = int(round(duration / dt))
    period = cfg.cpg_update_period_s or morph.control.cpg_update_period_s
    cpg_every = max(1, int(round(period / dt)))
    check_every = max(1, int(round(cfg.check_every_s / dt)))
    record_every = None if cfg.record_every_s is None else max(1, int(round(cfg.record_every_s / dt)))
    motor = MOTOR_MODELS[cfg.motor_model]

    engine = EngineSettings(dt_s=dt, solver_iterations=cfg.solver_iterations, friction_anchor=cfg.friction_anchor)
    nodes = morph.structure.node_array()
    terrain = build_terrain(cfg.scene, cfg.ground_friction if cfg.ground_friction is not None
                            else morph.ground_friction, (float(nodes[:, 2].min()), float(nodes[:, 2].max())))
    rotation = start_rotation(cfg.scene)
    lift = start_lift_cm(terrain, morph, rotation)
    if lift > 0:
        offsets = np.zeros((len(bodies), 3)) if offsets is None else offsets
        offsets[:, 1] += lift
    scene = (scene_factory or PhysicsScene)(bodies, engine, terrain, offsets, rotation)
    cpg = CpgIntegrator(network, cfg.cpg_max_step_s)
    cpg_out = cpg.output_cm_s
    bank = sk.StringBank(len(bodies), geom.body_a, geom.body_b, geom.anchor_a_cm, geom.anchor_b_cm,
                         sparams, sstate)
    sstate = bank.state
    traj = Trajectory() if record_every else None
    reason = ""
    try:
        poses = scene.read_poses()
        last_check = poses[:, :3].copy()
        com_path = [scoring.robot_com_cm(poses, masses)]
        # partial metrics of a diverged trial come from the last sane check
        last_good, last_good_step, last_good_work = poses.copy(), 0, 0.0
        read, apply, step, advance = scene.read_poses, scene.apply_force_pairs, scene.step, cpg.advance
        strings_step, points, forces, tension = bank.step, bank.points, bank.forces, bank.tension
        steps_done = 0
        for n in range(n_steps):
            if n:
                poses = read()
            if (n + 1) % cpg_every == 0:
                advance(cpg_every * dt)  # the time that really elapsed, also when dt > the period
            if strings_step(poses, cpg_out, dt, motor) != sk.STATUS_OK:
                reason = f"diverged: non-finite string state at t={n * dt:.3f} s"
                break
            if record_every and n % record_every == 0:
                _record(traj, n * dt, poses, tension, cpg_out, sstate)
            apply(points, forces)
            step()
            steps_done = n + 1
            if steps_done % check_every == 0:
                poses = read()
                reason = _check(poses, last_check, masses, sstate, geom.start_length_cm, check_every * dt, cfg,
                                terrain)
                last_check = poses[:, :3].copy()
                if reason:
                    reason = f"{reason} at t={steps_done * dt:.3f} s"
                    break
                com_path.append(scoring.robot_com_cm(poses, masses))
                last_good, last_good_step, last_good_work = poses.copy(), steps_done, float(bank.work[0])
        end_poses = scene.read_poses()
        if not reason and not np.all(np.isfinite(end_poses)):
            reason = "diverged: non-finite pose"
        if record_every and not reason:
            _record(traj, steps_done * dt, end_poses, tension, cpg_out, sstate)
    finally:
        scene.close()

    if reason:  # never score an exploded state: report what was measured up to the last sane check
        end_poses, steps_done = last_good, last_good_step
        bank.work[0] = last_good_work
    sim_time = steps_done * dt
    build = _build_poses(bodies, lift, rotation)  # the start pose without jitter: distances count from it
    start_com = scoring.robot_com_cm(build, masses)
    distance_cm = scoring.planar_distance_cm(start_com, scoring.robot_com_cm(end_poses, masses))
    seg = morph.scored_segment
    seg_start = build[seg, :3]
    ntrt_cm = scoring.planar_distance_cm(seg_start, end_poses[seg, :3])
    work_j = float(bank.work[0]) * scoring.WORK_J_PER_INTERNAL
    distance_m = distance_cm * scoring.CM
    result = TrialResult(
        status=TrialStatus.FAILED if reason else TrialStatus.COMPLETE, reason=reason,
        distance_m=distance_m, ntrt_distance_cm=ntrt_cm,
        speed_cm_s=distance_cm / sim_time if sim_time > 0 else 0.0,
        work_j=work_j, cot=scoring.cost_of_transport(work_j, total_mass, distance_m),
        sim_time_s=sim_time, wall_time_s=time.perf_counter() - t_wall, mass_kg=total_mass, seed=int(seed),
        extras={"dt_s": dt},
    )
    path = np.array(com_path)
    return TrialOutcome(result, traj, path, np.arange(len(path)) * check_every * dt)


@lru_cache(maxsize=64)
def _stable_step(morph: Morphology, relocate: bool):
    from worker.sim.stability import estimate_stable_step

    return estimate_stable_step(morph, relocate)


def choose_step(morph: Morphology, cfg: TrialConfig) -> float:
    """The physics step: dt_s, or the automatic choice; refuses a step known to be unstable."""
    est = _stable_step(morph, cfg.relocate_anchors)
    if cfg.auto_dt:
        return min(cfg.dt_s, cfg.dt_safety_factor * est.dt_limit_s)
    if cfg.refuse_unstable_dt and cfg.dt_s > est.dt_limit_s:
        raise ConfigError(
            f"dt_s is unstable for {morph.name}: its string network has omega_max = {est.omega_max_rad_s:.4g} rad/s "
            f"and gamma_max = {est.gamma_max_per_s:.4g} 1/s, so explicit string forces diverge above "
            f"dt = {est.dt_limit_s:.3g} s; set auto_dt (--dt auto) or a smaller step",
            received=cfg.dt_s, expected=f"dt_s <= {est.dt_limit_s:.3g} s")
    return cfg.dt_s


def _rotation_matrix(rotation: tuple[float, float, float, float] | None) -> np.ndarray:
    if rotation is None:
        return np.eye(3)
    x, y, z, w = rotation
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def start_rotation(scene: SceneConfig) -> tuple[float, float, float, float] | None:
    """On a slope the robot starts lying on it: its build pose tilted like the plane."""
    if scene.kind != "slope" or scene.slope_deg == 0.0:
        return None
    a = math.radians(scene.slope_deg)
    return (math.sin(a / 2), 0.0, 0.0, math.cos(a / 2))


def _build_poses(bodies, lift_cm: float = 0.0, rotation=None) -> np.ndarray:
    """Start poses without jitter (tilted on a slope, lifted clear of the terrain)."""
    rot = _rotation_matrix(rotation)
    q = (0.0, 0.0, 0.0, 1.0) if rotation is None else rotation
    return np.array([[*(rot @ b.com_cm + np.array([0.0, lift_cm, 0.0])), *q] for b in bodies])


def start_lift_cm(terrain, morph: Morphology, rotation=None) -> float:
    """How far to raise the robot so that no point along its rods starts lower above the terrain
    than it would above flat ground (0 on flat ground)."""
    nodes = morph.structure.node_array() @ _rotation_matrix(rotation).T
    ends = np.array([(r.a, r.b) for r in morph.structure.rods])
    t = np.linspace(0.0, 1.0, 9)[:, None, None]
    pts = (nodes[ends[:, 0]][None] * (1 - t) + nodes[ends[:, 1]][None] * t).reshape(-1, 3)
    surface = surface_height_cm(terrain, pts[:, 0], pts[:, 2])
    return float(max(0.0, (surface - GROUND_TOP_CM).max()))


def _record(traj: Trajectory, t: float, poses, tension, cpg_out, sstate) -> None:
    traj.time_s.append(t)
    traj.poses.append(poses.copy())
    traj.tension_n.append(tension / NEWTON)
    traj.cpg_output_cm_s.append(cpg_out.copy())
    traj.rest_length_cm.append(sstate[:, sk.S_REST].copy())


def _check(poses: np.ndarray, last: np.ndarray, masses: np.ndarray, sstate: np.ndarray,
           start_length: np.ndarray, interval_s: float, cfg: TrialConfig, terrain) -> str:
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
    surface = np.where(np.isfinite(surface), surface, GROUND_TOP_CM)  # off the terrain's edge: ground level
    y_m = (poses[:, 1] - surface) * scoring.CM
    if y_m.min() < cfg.min_height_m or y_m.max() > cfg.max_height_m:
        b = int(np.argmax(np.maximum(cfg.min_height_m - y_m, y_m - cfg.max_height_m)))
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


def run_trial(morphology: Morphology | str | Mapping, params: np.ndarray | Mapping[str, float] | list,
              config: TrialConfig | None = None, seed: int = 0, *, controller: str | None = None) -> TrialResult:
    """One trial -> TrialResult. `params`: unit-cube vector of the controller space, or a mapping of
    named physical values. Divergence is a failed result, never an exception; bad parameters raise
    ParameterError."""
    return simulate(morphology, params, config, seed, controller=controller).result


def random_unit_params(morph: Morphology, seed: int, controller: str | None = None) -> np.ndarray:
    """A seeded uniform sample of the controller space's unit cube."""
    return np.random.default_rng(seed).random(len(morph.param_space(controller)))


