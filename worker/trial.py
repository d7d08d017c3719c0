"""The trial loop: CPG -> impedance -> motor -> strings -> engine, once per physics step.

The start pose, guards and score live in worker.episode; the engine behind worker.engines.base.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from spinefarm.protocol.errors import ConfigError, ParameterError
from spinefarm.protocol.messages import TrialResult
from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.morphology.structure import NEWTON
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker import scoring
from spinefarm.worker.control.cpg import CpgIntegrator
from spinefarm.worker.engines.base import EngineFactory
from spinefarm.worker.episode import check_state, choose_step, score
from spinefarm.worker.setup import SetupCache, TrialSetup, setup_key
from spinefarm.worker.sim import strings as sk

MOTOR_MODELS = {"physical": sk.MOTOR_PHYSICAL, "ntrt2014": sk.MOTOR_NTRT2014}
__all__ = ["Trajectory", "TrialConfig", "TrialOutcome", "choose_step", "random_unit_params", "run_trial", "simulate"]


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


class _ContactsNeeded(Exception):
    """An engine left out contacts (MuJoCo's segment_contacts "auto") that this trial may need."""


def simulate(morphology: Morphology | str | Mapping, params: np.ndarray | Mapping[str, float] | list,
             config: TrialConfig | None = None, seed: int = 0, *, controller: str | None = None,
             scene_factory: EngineFactory | None = None, setup: TrialSetup | SetupCache | None = None
             ) -> TrialOutcome:
    """Run one trial and return its result with the recorded trajectory (if config asks for one).
    `scene_factory` replaces the configured engine's class (same constructor as BasePhysics).
    `setup`: a TrialSetup of this morphology and config, or a SetupCache, to reuse what earlier trials
    built (the result is the same bits either way)."""
    cfg = config or TrialConfig()
    try:
        return _simulate(morphology, params, cfg, seed, controller, scene_factory, setup)
    except _ContactsNeeded as why:  # run again from the start with every contact the scene has
        options = {**cfg.engine_options, "segment_contacts": "scene"}
        if isinstance(setup, TrialSetup):
            setup = None
        out = _simulate(morphology, params, dataclasses.replace(cfg, engine_options=options), seed, controller,
                        scene_factory, setup)
        out.result.extras["segment_contacts"] = f"modelled: {why}"
        return out


def _simulate(morphology, params, cfg: TrialConfig, seed: int, controller: str | None,
              scene_factory: EngineFactory | None, setup: TrialSetup | SetupCache | None) -> TrialOutcome:
    t_wall = time.perf_counter()
    morph = load_morphology(morphology)
    controller = controller or cfg.controller
    physical = resolve_params(morph, params, controller)
    network = morph.controller_space(controller).network(physical)
    if not isinstance(seed, int | np.integer):
        raise ParameterError("seed is not an integer", received=seed, expected="an integer")
    if isinstance(setup, SetupCache):
        setup = setup.get(morph, cfg, controller)
    elif setup is None or setup.morph != morph or setup_key(setup.cfg) != setup_key(cfg) \
            or setup.controller != controller:
        setup = TrialSetup(morph, cfg, controller)
    sparams, sstate = setup.string_tables(network)
    bodies, geom, masses, dt, terrain = setup.bodies, setup.geom, setup.masses, setup.dt, setup.terrain

    duration = cfg.duration_s or morph.duration_s
    n_steps = int(round(duration / dt))
    n_settle = int(round(cfg.settle_s / dt))
    period = cfg.cpg_update_period_s or morph.control.cpg_update_period_s
    cpg_every = max(1, int(round(period / dt)))
    check_every = max(1, int(round(cfg.check_every_s / dt)))
    record_every = None if cfg.record_every_s is None else max(1, int(round(cfg.record_every_s / dt)))
    motor = MOTOR_MODELS[cfg.motor_model]

    scene, owned = setup.scene(setup.start_offsets(int(seed)), scene_factory)
    cpg = CpgIntegrator(network, cfg.cpg_max_step_s)
    cpg_out = cpg.output_cm_s
    bank = sk.StringBank(len(bodies), geom.body_a, geom.body_b, geom.anchor_a_cm, geom.anchor_b_cm,
                         sparams, sstate)
    sstate = bank.state
    traj = Trajectory() if record_every else None
    # the compiled loop of an engine that offers one; recording goes step by step in Python
    fused = getattr(scene, "fused_stepper", None) if record_every is None else None
    reason = ""
    settle_poses, settle_work = None, 0.0
    try:
        poses = scene.read_poses().copy()
        last_check = poses[:, :3].copy()
        com_path = [scoring.robot_com_cm(poses, masses)]
        # partial metrics of a diverged trial come from the last sane check
        last_good, last_good_step, last_good_work = poses.copy(), 0, 0.0
        steps_done = 0  # since the start, settle included
        # an engine that leaves contacts out says how many steps are safe without them; look again then
        free_steps = getattr(scene, "contact_free_steps", None)
        safe_until = _safe_until(free_steps, 0, check_every, dt)
        # the settle phase holds the CPG at rest (zero output): the impedance reflex holds the posture
        for phase_steps, every in ((n_settle, 0), (n_steps, cpg_every)):
            if reason:
                break
            if phase_steps and fused is not None:
                run = fused(bank, cpg, every, motor).run
            else:
                run = _python_steps(scene, bank, cpg, every, dt, motor, traj, record_every, steps_done)
            n = 0
            while n < phase_steps:
                stop = min(phase_steps, n + check_every - steps_done % check_every, n + safe_until - steps_done)
                status, reached = run(n, stop)
                steps_done += reached - n
                if status != sk.STATUS_OK:
                    reason = f"diverged: non-finite string state at t={steps_done * dt:.3f} s"
                    break
                n = stop
                if steps_done == safe_until:
                    safe_until = _safe_until(free_steps, steps_done, check_every, dt)
                if steps_done % check_every == 0:
                    poses = scene.read_poses()
                    reason = check_state(poses, last_check, masses, sstate, geom.start_length_cm, check_every * dt,
                                         cfg, terrain)
                    last_check = poses[:, :3].copy()
                    if reason:
                        reason = f"{reason} at t={steps_done * dt:.3f} s"
                        break
                    com_path.append(scoring.robot_com_cm(poses, masses))
                    last_good, last_good_step, last_good_work = poses.copy(), steps_done, float(bank.work[0])
            if every == 0 and n_settle and not reason:  # locomotion is scored from here
                settle_poses, settle_work = scene.read_poses().copy(), float(bank.work[0])
        end_poses = scene.read_poses().copy()
        if not reason and not np.all(np.isfinite(end_poses)):
            reason = "diverged: non-finite pose"
        if record_every and not reason:
            _record(traj, steps_done * dt, end_poses, bank.tension, cpg_out, sstate)
    finally:
        if owned:
            scene.close()

    if reason:  # never score an exploded state: report what was measured up to the last sane check
        end_poses, steps_done = last_good, last_good_step
        bank.work[0] = last_good_work
    loco_steps = max(0, steps_done - n_settle) if settle_poses is not None else 0 if n_settle else steps_done
    extras = {"dt_s": dt, "engine": cfg.engine, "settle_s": n_settle * dt}
    # the start pose without jitter (or the pose after the settle): distances count from it
    result = score(morph, masses, setup.build, end_poses, loco_steps, dt, float(bank.work[0]) - settle_work, reason,
                   int(seed), time.perf_counter() - t_wall, extras, start=settle_poses)
    path = np.array(com_path)
    return TrialOutcome(result, traj, path, np.arange(len(path)) * check_every * dt)


def _safe_until(free_steps, steps_done: int, check_every: int, dt: float) -> int:
    """The step before which the engine's left-out contacts cannot form (it looks at most a check ahead)."""
    if free_steps is None:
        return 1 << 62
    steps, why = free_steps(check_every)
    if steps == 0:
        raise _ContactsNeeded(f"{why} at t={steps_done * dt:.3f} s")
    return steps_done + steps


def _python_steps(scene, bank, cpg, every: int, dt: float, motor: int, traj, record_every, base: int):
    """The loop step by step through the engine seam: steps n0 .. n1-1 of a phase starting at global
    step `base`. Returns (status, step reached) like a fused stepper."""
    read, apply, step, advance = scene.read_poses, scene.apply_wrenches, scene.step, cpg.advance
    strings_step, force, torque, tension, sstate = bank.step, bank.force, bank.torque, bank.tension, bank.state
    cpg_out = cpg.output_cm_s

    def run(n0: int, n1: int) -> tuple[int, int]:
        for n in range(n0, n1):
            poses = read()
            if every and (n + 1) % every == 0:
                advance(every * dt)  # the time that really elapsed, also when dt > the period
            if strings_step(poses, cpg_out, dt, motor) != sk.STATUS_OK:
                return sk.STATUS_NONFINITE, n
            if record_every and (base + n) % record_every == 0:
                _record(traj, (base + n) * dt, poses, tension, cpg_out, sstate)
            apply(force, torque)
            step()
        return sk.STATUS_OK, n1

    return run


def run_trial(morphology: Morphology | str | Mapping, params: np.ndarray | Mapping[str, float] | list,
              config: TrialConfig | None = None, seed: int = 0, *, controller: str | None = None,
              setup: TrialSetup | SetupCache | None = None) -> TrialResult:
    """One trial -> TrialResult. `params`: unit-cube vector of the controller space, or a mapping of
    named physical values. Divergence is a failed result, never an exception; bad parameters raise
    ParameterError."""
    return simulate(morphology, params, config, seed, controller=controller, setup=setup).result


def random_unit_params(morph: Morphology, seed: int, controller: str | None = None) -> np.ndarray:
    """A seeded uniform sample of the controller space's unit cube."""
    return np.random.default_rng(seed).random(len(morph.param_space(controller)))




def _record(traj: Trajectory, t: float, poses, tension, cpg_out, sstate) -> None:
    traj.time_s.append(t)
    traj.poses.append(poses.copy())
    traj.tension_n.append(tension / NEWTON)
    traj.cpg_output_cm_s.append(cpg_out.copy())
    traj.rest_length_cm.append(sstate[:, sk.S_REST].copy())
