"""The control law: the CPG and the string law as one step, poses in, one net wrench per body out, for a
batch of B worlds.

Per world and physics step (`law_step_world`, compiled once and used by every loop in worker.trial.loop): advance
the CPG by its update period when one is due, then run the string kernel (impedance -> motor -> string law ->
per-body wrench). The CPG either holds its output between updates (NTRT's controlTime, updated at the end of
each period) or, at its own step longer than the physics step, runs one update ahead and the setpoints between
two updates are interpolated linearly (exact at the update instants). The CPG, the string parameters and every
buffer carry a leading world axis, so the worlds of a batch may hold different parameter sets (and CPG
couplings), each with its own state and CPG step; the string geometry is the robot's and shared.

Compiled structures are plain tuples of arrays (numba types them once):
  cpg     (state (B, n, 3), omega (B, n), amp (B, n), indptr (B, n+1), source (B, e), wc (B, 2e) complex
           weights as re, im pairs,
           rate (B,), h (B,), n_sub (B,), scratch (B, 9, n, 3), output (B, n) cm/s (the setpoints the strings
           read), ahead and behind (B, n): the outputs at the next and the last update when interpolating)
  strings (body_a (s,), body_b (s,), anchor_a (s, 3), anchor_b (s, 3) cm, params (B, s, N_PARAM),
           state (B, s, N_STATE), force (B, nb, 3), torque (B, nb, 3), tension (B, s), work (B, 1),
           world anchors a, b (B, s, 3), string force (B, s, 3))
  clock   (steps (B,) int64 taken in this phase, cpg_every (B,) (steps per CPG update, 0: CPG held), dt_s,
           motor mode, quiet (B,) int64: 1 until the world's first step, which then runs without the law (motor
           ntrt2026), interpolate (B,) (1: setpoints interpolated between updates, 0: held))
"""

from __future__ import annotations

import numpy as np
from numba import njit

from spinefarm.protocol.errors import ConfigError
from spinefarm.robot.cpg_network import CpgNetwork
from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.morphology.structure import NEWTON
from spinefarm.worker.control.cpg import CpgIntegrator, rk4_advance
from spinefarm.worker.sim import strings as sk

MOTOR_MODELS = {"physical": sk.MOTOR_PHYSICAL, "ntrt2014": sk.MOTOR_NTRT2014, "ntrt2026": sk.MOTOR_NTRT2026}
STATUS_OK, STATUS_NONFINITE = sk.STATUS_OK, sk.STATUS_NONFINITE


MIN_START_LENGTH_CM = 1e-3  # a string shorter at the start has coinciding ends (overlapping segments)


@njit(cache=True)
def law_step_world(cpg, strings, clock, b, poses):
    """One step of world b: poses (nb, 7) COM cm + quaternion x, y, z, w -> strings' force[b], torque[b]
    (nb, 3). Returns the string kernel's status; the world's step count advances only on success."""
    state, omega, amp, indptr, source, wc, rate, h, n_sub, scratch, out, ahead, behind = cpg
    body_a, body_b, anc_a, anc_b, params, sstate, force, torque, tension, work, wa, wb, sforce = strings
    steps, every_b, dt, motor, quiet, interpolate = clock
    if quiet[b]:  # NTRT's first world step runs before its first model step: no string forces, no control
        quiet[b] = 0
        force[b][:] = 0.0
        torque[b][:] = 0.0
        return STATUS_OK
    n = steps[b]
    every = every_b[b]
    net = (omega[b], amp[b], indptr[b], source[b], wc[b], rate[b])
    if every > 0 and interpolate[b]:
        k = n % every
        if k == 0:  # a new interval: its far end is the next update, computed now
            behind[b, :] = ahead[b]
            rk4_advance(state[b], net, h[b], n_sub[b], scratch[b], ahead[b])
        frac = (k + 1) / every
        for i in range(out.shape[1]):
            out[b, i] = behind[b, i] + frac * (ahead[b, i] - behind[b, i])
    elif every > 0 and (n + 1) % every == 0:
        rk4_advance(state[b], net, h[b], n_sub[b], scratch[b], out[b])
    status = sk.string_step(poses, (body_a, body_b, anc_a, anc_b), params[b], sstate[b], out[b], dt, motor,
                            (force[b], torque[b], tension[b], work[b], wa[b], wb[b], sforce[b]))
    if status == STATUS_OK:
        steps[b] = n + 1
    return status


@njit(cache=True)
def law_step(cpg, strings, clock, poses, active, status):
    """One step of every active world: poses (B, nb, 7); status (B,) receives each world's status. Returns
    how many active worlds failed."""
    failed = 0
    for b in range(poses.shape[0]):
        if active[b]:
            status[b] = law_step_world(cpg, strings, clock, b, poses[b])
            failed += status[b] != STATUS_OK
    return failed


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
        if mat.motor_radius_cm is not None:
            params[i, sk.P_RHO] = mat.motor_radius_cm
            params[i, sk.P_J] = mat.motor_inertia_kg_cm2
            params[i, sk.P_C] = mat.motor_friction_kg_cm2_s
            params[i, sk.P_KP] = mat.tension_pd_p_cm
            params[i, sk.P_KD] = mat.tension_pd_d_cm_s
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
        if start_length_cm[i] < MIN_START_LENGTH_CM:  # the pretension test below would contradict itself
            raise ConfigError(
                f"string {i} ({s.tag}, nodes {s.a} -> {s.b}) has no length at the start: its ends coincide, so "
                "two segments overlap; move them apart in the spec (segments: transforms) and run "
                "`spinefarm check` on it", received=f"{start_length_cm[i]:.3g} cm",
                expected=f"a start length of at least {MIN_START_LENGTH_CM:g} cm")
        rest = start_length_cm[i] - mat.pretension_n * NEWTON / k
        if rest <= 0:
            raise ConfigError(f"pretension of string {i} ({s.tag}) exceeds k * start length",
                              received=mat.pretension_n, expected=f"< {k * start_length_cm[i] / NEWTON:.3g} N")
        state[i, sk.S_REST] = rest
        state[i, sk.S_LPREV] = start_length_cm[i]
    return params, state


def _stack(arrays: list[np.ndarray], dtype: type) -> np.ndarray:
    """(B, max length) of 1-D arrays, zero-padded (a world reads only its own length)."""
    out = np.zeros((len(arrays), max((a.shape[0] for a in arrays), default=0)), dtype=dtype)
    for b, a in enumerate(arrays):
        out[b, :a.shape[0]] = a
    return out


class ControlLaw:
    """The CPG and string state of B worlds. networks: one CpgNetwork per world; tables: one (params, state)
    pair of string_tables per world; geom: the robot's string geometry (body_a, body_b, anchor_a_cm,
    anchor_b_cm); cpg_max_step_s: the CPG's RK4 sub-step cap (None: CpgIntegrator's default)."""

    def __init__(self, networks: list[CpgNetwork], tables: list[tuple[np.ndarray, np.ndarray]],
                 geom: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
                 n_bodies: int, cpg_max_step_s: float | None, motor_model: str) -> None:
        n_worlds = len(networks)
        if len({n.n_nodes for n in networks}) != 1 or len(tables) != n_worlds:
            raise ConfigError("the worlds of a batch need one controller space", received=[n.n_nodes for n in networks],
                              expected="as many CPG nodes in every world, and one string table per world")
        self.n_worlds = n_worlds
        self.motor = MOTOR_MODELS[motor_model]
        self._cpgs = [CpgIntegrator(net, cpg_max_step_s) for net in networks]  # each world's RK4 plan
        n_nodes = networks[0].n_nodes
        self.cpg_state = np.zeros((n_worlds, n_nodes, 3))
        self.cpg_output_cm_s = np.zeros((n_worlds, n_nodes))
        self._cpg_const = (self.cpg_state, _stack([n.omega_rad_s.astype(np.float64) for n in networks], np.float64),
                           _stack([n.amplitude_cm_s.astype(np.float64) for n in networks], np.float64),
                           _stack([n.indptr.astype(np.int64) for n in networks], np.int64),
                           _stack([n.source.astype(np.int64) for n in networks], np.int64),
                           _stack([c.kernel_arrays()[4] for c in self._cpgs], np.float64),  # weights once
                           np.array([float(n.amplitude_rate_per_s) for n in networks]))
        self._scratch = np.zeros((n_worlds, 9, n_nodes, 3))
        self._ahead = np.zeros((n_worlds, n_nodes))
        self._behind = np.zeros((n_worlds, n_nodes))
        n_strings = tables[0][0].shape[0]
        self.params = np.ascontiguousarray(np.stack([t[0] for t in tables]), dtype=np.float64)
        self.state = np.ascontiguousarray(np.stack([t[1] for t in tables]), dtype=np.float64)
        self.force = np.zeros((n_worlds, n_bodies, 3))
        self.torque = np.zeros((n_worlds, n_bodies, 3))
        self.tension = np.zeros((n_worlds, n_strings))
        self.work = np.zeros((n_worlds, 1))
        body_a, body_b, anchor_a, anchor_b = geom
        self.strings = (np.ascontiguousarray(body_a, dtype=np.int64), np.ascontiguousarray(body_b, dtype=np.int64),
                        np.ascontiguousarray(anchor_a, dtype=np.float64),
                        np.ascontiguousarray(anchor_b, dtype=np.float64), self.params, self.state, self.force,
                        self.torque, self.tension, self.work, np.zeros((n_worlds, n_strings, 3)),
                        np.zeros((n_worlds, n_strings, 3)), np.zeros((n_worlds, n_strings, 3)))
        self.steps = np.zeros(n_worlds, dtype=np.int64)
        self.status = np.zeros(n_worlds, dtype=np.int64)
        # NTRT's current code steps the world once before the model's first step (its recordings' t = 0 row)
        self.quiet = np.full(n_worlds, int(self.motor == sk.MOTOR_NTRT2026), dtype=np.int64)
        self.begin_phase(0, 1.0)

    def begin_phase(self, cpg_every: int, dt_s: float, own_step_s: float | None = None) -> None:
        """Start a phase: the CPG advances every cpg_every steps by cpg_every * dt_s, its output held until the
        next update (0: held at rest, as in a settle phase). With own_step_s (and cpg_every 1) each world's CPG
        runs at its own step instead: the largest multiple of dt_s within own_step_s and its network's
        SLOW_RATE_STEP / fastest rate, by one RK4 step (sub-steps only under an explicit cpg_max_step_s) one
        update ahead, the setpoints in between interpolated. Step counts start again from 0."""
        every = np.full(self.n_worlds, max(0, int(cpg_every)), dtype=np.int64)
        if own_step_s and cpg_every == 1:
            every[:] = [max(1, int(min(own_step_s, c.own_step_s()) / dt_s + 1e-9)) for c in self._cpgs]
        interpolate = (every > 1).astype(np.int64) if own_step_s and cpg_every == 1 else np.zeros_like(every)
        plans = [(0.0, 0) if e <= 0 else c.plan(e * dt_s, e * dt_s if i else None)
                 for c, e, i in zip(self._cpgs, every, interpolate, strict=True)]
        h = np.array([p[0] for p in plans], dtype=np.float64)
        n_sub = np.array([p[1] for p in plans], dtype=np.int64)
        self.cpg_every = every
        self._ahead[:] = self.cpg_output_cm_s  # the output now: the near end of the first interval
        self.cpg = (*self._cpg_const, h, n_sub, self._scratch, self.cpg_output_cm_s, self._ahead, self._behind)
        self.steps[:] = 0
        self.clock = (self.steps, every, float(dt_s), int(self.motor), self.quiet, interpolate)

    def step(self, poses: np.ndarray, active: np.ndarray) -> int:
        """One step of every active world: poses (B, nb, 7) -> self.force, self.torque (B, nb, 3). Returns how
        many active worlds failed; self.status (B,) says which (STATUS_NONFINITE: that world's step was not
        taken)."""
        return law_step(self.cpg, self.strings, self.clock, poses, active, self.status)

    def _world_arrays(self) -> tuple[np.ndarray, ...]:
        """Every array that carries a world's law from one step to the next (scratch and per-step outputs
        aside, which each step writes before reading)."""
        return (self.cpg_state, self.cpg_output_cm_s, self._ahead, self._behind, self.state, self.work,
                self.tension, self.force, self.torque, self.steps, self.quiet)

    def snapshot(self, world: int) -> tuple[np.ndarray, ...]:
        """World `world`'s law state mid-phase (copies): with the engine's snapshot of the world, all a trial
        needs to go on later from this step."""
        return tuple(np.array(a[world], copy=True) for a in self._world_arrays())

    def restore(self, world: int, saved: tuple[np.ndarray, ...]) -> None:
        """World `world` takes a snapshot(); the law must be in the phase it was taken in (begin_phase with the
        same arguments), which fixes the CPG's plan."""
        for a, s in zip(self._world_arrays(), saved, strict=True):
            a[world] = s

    def work_internal(self, world: int) -> float:
        """Reel-in work of world `world` so far, internal units (kg cm^2/s^2)."""
        return float(self.work[world, 0])
