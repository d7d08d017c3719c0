"""The string kernel: anchors, lengths, impedance, motor, force law and per-body wrenches in one pass.

One compiled call per physics step, nothing per string in Python. Internal units: cm, kg, s;
forces in kg*cm/s^2 (1 N = 100). Columns of the packed arrays are named below.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# params (n_strings, N_PARAM)
P_K, P_B, P_TMAX, P_V, P_A, P_LMIN, P_LACT, P_T0, P_KI, P_BI, P_LC, P_MODE, P_NODE, P_DRIVE = range(14)
# NTRT's kinematic motor (radius 0: none): spool radius, inertia, viscous friction, PD gains on tension
P_RHO, P_J, P_C, P_KP, P_KD = range(14, 19)
N_PARAM = 19
# state (n_strings, N_STATE): rest length, length at the previous evaluation, its rate, motor speed (the
# kinematic motor's spool rate, rad/s), the tension error at the previous step (kinematic motor's PD)
S_REST, S_LPREV, S_V, S_U, S_ERR = range(5)
N_STATE = 5

MODE_FIXED, MODE_IMPEDANCE, MODE_DRIVEN = 0, 1, 2
MOTOR_PHYSICAL, MOTOR_NTRT2014, MOTOR_NTRT2026 = 0, 1, 2

STATUS_OK, STATUS_NONFINITE = 0, 1


@njit(cache=True, inline="always")
def _sign(x):
    return 1.0 if x > 0.0 else (-1.0 if x < 0.0 else 0.0)


@njit(cache=True)
def motor_physical(rest, target, length, k, tmax, vmax, amax, lmin, lact, u, dt):
    """Rest-length motor with speed and acceleration limits in physical units (dt-independent).

    Returns (new rest length, new motor speed). It approaches the target on a profile that can stop
    in time (speed <= sqrt(2 A |delta|)), never shortens the string while its tension exceeds tmax,
    and never goes below lmin.
    """
    tension = k * (length - rest)
    if k * (length - target) > tmax:
        target = length - tmax / k
    delta = target - rest
    if not (length > lact or delta > 0.0):
        delta = 0.0
    mag = abs(delta)
    speed = min(vmax, np.sqrt(2.0 * amax * mag), mag / dt) * _sign(delta)
    dv = speed - u
    lim = amax * dt
    if dv > lim:
        dv = lim
    elif dv < -lim:
        dv = -lim
    u_new = u + dv
    if tension > tmax and u_new < 0.0:
        u_new = 0.0  # brake: no reeling in above the tension limit
    new_rest = rest + u_new * dt
    if new_rest < lmin:
        new_rest = lmin
        u_new = 0.0
    return new_rest, u_new


@njit(cache=True)
def motor_ntrt2014(rest, target, length, k, tmax, vmax, amax, lmin, lact, vc, dt):
    """NTRT's 2014 per-step motor (spec 3.3 [P]); its caps V dt and A dt^2 tie speed to dt."""
    s = vmax * dt
    a = amax * dt
    if k * (length - target) > tmax:
        target = length - tmax / k
    delta = target - rest
    if length > lact or delta > 0.0:
        if abs(delta) > s:
            if abs(_sign(delta) * vmax - vc) > a:
                s = a * dt
            rest += _sign(delta) * s
        else:
            if abs(delta / dt - vc) > a:
                delta = _sign(delta) * a * dt
                if delta == 0.0:
                    delta = -_sign(vc) * a * dt
            rest += delta
    if rest < lmin:
        rest = lmin
    return rest


@njit(cache=True)
def motor_ntrt2026(rest, target, length, k, tmax, vmax, lmin, lact, dt):
    """NTRT's current motor (spec 3.3 [H], since 2014-12): the 2014 rules without the acceleration limit,
    each step's move clamped to V dt. Its recorded runs (ntrt-recordings) were made with it."""
    if k * (length - target) > tmax:
        target = length - tmax / k
    delta = target - rest
    if length > lact or delta > 0.0:
        step = vmax * dt
        rest += min(max(delta, -step), step)
    if rest < lmin:
        rest = lmin
    return rest


@njit(cache=True)
def motor_kinematic(rest, tension, tau_cmd, omega, rho, inertia, friction, tmax, vmax, lmin, dt):
    """NTRT's current kinematic motor (spec 3.3 [H]), not back-drivable: the commanded spool torque within
    a torque-speed limit, the string's tension and viscous friction accelerate the spool; while the net
    acceleration opposes the torque the spool may not turn outward. Returns (rest length, spool rate)."""
    tau_max = tmax * rho * max(0.0, 1.0 - rho * abs(omega) / vmax)
    tau = min(max(tau_cmd, -tau_max), tau_max)
    acc = (tau - friction * omega + tension * rho) / inertia
    omega = omega + acc * dt
    if acc * tau <= 0.0 and omega > 0.0:
        omega = 0.0
    rest = rest + rho * omega * dt
    if rest < lmin:
        rest = lmin
    return rest, omega


@njit(cache=True, inline="always")
def _quat_to_matrix(q, r):
    """r (3, 3) = the rotation of quaternion q (x, y, z, w)."""
    x, y, z, w = q[0], q[1], q[2], q[3]
    r[0, 0] = 1 - 2 * (y * y + z * z)
    r[0, 1] = 2 * (x * y - z * w)
    r[0, 2] = 2 * (x * z + y * w)
    r[1, 0] = 2 * (x * y + z * w)
    r[1, 1] = 1 - 2 * (x * x + z * z)
    r[1, 2] = 2 * (y * z - x * w)
    r[2, 0] = 2 * (x * z - y * w)
    r[2, 1] = 2 * (y * z + x * w)
    r[2, 2] = 1 - 2 * (x * x + y * y)


@njit(cache=True)
def body_rotations(poses, rots):
    """rots (nb, 3, 3) = each body's rotation matrix from poses (nb, 7)."""
    for b in range(poses.shape[0]):
        _quat_to_matrix(poses[b, 3:7], rots[b])


@njit(cache=True)
def _anchors(poses, rots, body, anchors, out):
    for i in range(anchors.shape[0]):
        b = body[i]
        for r in range(3):
            out[i, r] = poses[b, r] + rots[b, r, 0] * anchors[i, 0] + rots[b, r, 1] * anchors[i, 1] \
                + rots[b, r, 2] * anchors[i, 2]


@njit(cache=True)
def world_anchors(poses, body, anchors, out):
    """out (n, 3) = world positions of body-frame anchors (n, 3) on bodies posed by poses (nb, 7)."""
    rots = np.empty((poses.shape[0], 3, 3))
    body_rotations(poses, rots)
    _anchors(poses, rots, body, anchors, out)


@njit(cache=True)
def string_step(poses, geometry, params, state, cpg_out, dt, motor_mode, outputs):
    """One control + force step for every string.

    poses (nb, 7) COM position (cm) and quaternion (x, y, z, w); geometry = (body_a (n,), body_b (n,),
    anchor_a (n, 3), anchor_b (n, 3) cm body frame); params (n, N_PARAM), state (n, N_STATE); cpg_out
    (n_nodes,) cm/s. outputs = (out_force, out_torque, out_tension, work, wa, wb, string_force): writes
    out_force/out_torque (nb, 3), each body's net string force at its COM and torque about it (world
    frame), for the engine's one wrench write per body; out_tension (n,) spring tension
    max(0, k (L - rest)); adds reel-in work to work[0]; wa, wb (n, 3) world anchors (cm) and
    string_force (n, 3) the force on end a (end b gets its negative), kept for checks and recording.
    Returns STATUS_NONFINITE if any length or force is not finite.
    """
    body_a, body_b, anc_a, anc_b = geometry
    out_force, out_torque, out_tension, work, wa, wb, string_force = outputs
    nb = poses.shape[0]
    n = params.shape[0]
    rots = np.empty((nb, 3, 3))  # one allocation per step, both ends' anchors from the same matrices
    body_rotations(poses, rots)
    _anchors(poses, rots, body_a, anc_a, wa)
    _anchors(poses, rots, body_b, anc_b, wb)
    force = out_force
    torque = out_torque
    force[:] = 0.0
    torque[:] = 0.0
    status = STATUS_OK
    for i in range(n):
        dx = wb[i, 0] - wa[i, 0]
        dy = wb[i, 1] - wa[i, 1]
        dz = wb[i, 2] - wa[i, 2]
        length = np.sqrt(dx * dx + dy * dy + dz * dz)
        if not np.isfinite(length):
            status = STATUS_NONFINITE
            continue
        k = params[i, P_K]
        rest = state[i, S_REST]
        v_old = state[i, S_V]
        mode = params[i, P_MODE]
        new_rest = rest
        if mode != MODE_FIXED:
            if mode == MODE_IMPEDANCE:
                node = int(params[i, P_NODE])
                v0 = cpg_out[node] if node >= 0 else 0.0
                tension = max(0.0, k * (length - rest))
                # a kinematic motor reports its spool's speed as the string's velocity (NTRT [H])
                kinematic = motor_mode == MOTOR_NTRT2026 and params[i, P_RHO] > 0.0
                v_act = params[i, P_RHO] * state[i, S_U] if kinematic else v_old
                target_t = params[i, P_T0] + params[i, P_KI] * (length - params[i, P_LC]) \
                    + params[i, P_BI] * (v_act - v0)
                target_t = max(0.0, target_t)
                target = max(rest - (target_t - tension) / k, params[i, P_LMIN])
            else:
                target = params[i, P_DRIVE]
                tension = target_t = 0.0
                kinematic = False
            if kinematic:
                err = target_t - tension  # NTRT's tension PID, gains negated: more tension wanted -> reel in
                tau_cmd = -(params[i, P_KP] * err + params[i, P_KD] * (err - state[i, S_ERR]) / dt)
                state[i, S_ERR] = err
                new_rest, state[i, S_U] = motor_kinematic(
                    rest, tension, tau_cmd, state[i, S_U], params[i, P_RHO], params[i, P_J], params[i, P_C],
                    params[i, P_TMAX], params[i, P_V], params[i, P_LMIN], dt)
            elif motor_mode == MOTOR_PHYSICAL:
                new_rest, state[i, S_U] = motor_physical(
                    rest, target, length, k, params[i, P_TMAX], params[i, P_V], params[i, P_A],
                    params[i, P_LMIN], params[i, P_LACT], state[i, S_U], dt)
            elif motor_mode == MOTOR_NTRT2026:
                new_rest = motor_ntrt2026(rest, target, length, k, params[i, P_TMAX], params[i, P_V],
                                          params[i, P_LMIN], params[i, P_LACT], dt)
            else:
                new_rest = motor_ntrt2014(rest, target, length, k, params[i, P_TMAX], params[i, P_V],
                                          params[i, P_A], params[i, P_LMIN], params[i, P_LACT], v_old, dt)
            if new_rest < rest:
                work[0] += max(0.0, k * (length - rest)) * (rest - new_rest)
        v_new = (length - state[i, S_LPREV]) / dt
        f_spring = k * (length - new_rest)
        f_damp = params[i, P_B] * v_new
        if abs(f_damp) > abs(f_spring):
            f_damp = abs(f_spring) * _sign(f_damp)
        out_tension[i] = max(0.0, f_spring)
        string_force[i, 0] = 0.0
        string_force[i, 1] = 0.0
        string_force[i, 2] = 0.0
        state[i, S_REST] = new_rest
        state[i, S_LPREV] = length
        state[i, S_V] = v_new
        if length > new_rest and length > 0.0:
            f = (f_spring + f_damp) / length
            fx, fy, fz = f * dx, f * dy, f * dz
            string_force[i, 0] = fx
            string_force[i, 1] = fy
            string_force[i, 2] = fz
            a = body_a[i]
            b = body_b[i]
            ra0 = wa[i, 0] - poses[a, 0]
            ra1 = wa[i, 1] - poses[a, 1]
            ra2 = wa[i, 2] - poses[a, 2]
            rb0 = wb[i, 0] - poses[b, 0]
            rb1 = wb[i, 1] - poses[b, 1]
            rb2 = wb[i, 2] - poses[b, 2]
            force[a, 0] += fx
            force[a, 1] += fy
            force[a, 2] += fz
            torque[a, 0] += ra1 * fz - ra2 * fy
            torque[a, 1] += ra2 * fx - ra0 * fz
            torque[a, 2] += ra0 * fy - ra1 * fx
            force[b, 0] -= fx
            force[b, 1] -= fy
            force[b, 2] -= fz
            torque[b, 0] -= rb1 * fz - rb2 * fy
            torque[b, 1] -= rb2 * fx - rb0 * fz
            torque[b, 2] -= rb0 * fy - rb1 * fx
    for b in range(nb):
        for c in range(3):
            if not (np.isfinite(force[b, c]) and np.isfinite(torque[b, c])):
                status = STATUS_NONFINITE
    return status


class StringBank:
    """Every string of a scene: geometry, packed parameters, state and output buffers.

    body_a/body_b (n,), anchor_a_cm/anchor_b_cm (n, 3) body frame, params (n, N_PARAM),
    state (n, N_STATE). After step(): tension (n,) internal units, force/torque (nb, 3) each body's
    net wrench about its COM, wa/wb (n, 3) world anchors, string_force (n, 3) force on end a.
    """

    def __init__(self, n_bodies: int, body_a: np.ndarray, body_b: np.ndarray, anchor_a_cm: np.ndarray,
                 anchor_b_cm: np.ndarray, params: np.ndarray, state: np.ndarray) -> None:
        n = params.shape[0]
        self.body_a = np.ascontiguousarray(body_a, dtype=np.int64)
        self.body_b = np.ascontiguousarray(body_b, dtype=np.int64)
        self.anchor_a = np.ascontiguousarray(anchor_a_cm, dtype=np.float64)
        self.anchor_b = np.ascontiguousarray(anchor_b_cm, dtype=np.float64)
        self.params = np.ascontiguousarray(params, dtype=np.float64)
        self.state = np.ascontiguousarray(state, dtype=np.float64)
        self.force = np.zeros((n_bodies, 3))
        self.torque = np.zeros((n_bodies, 3))
        self.tension = np.zeros(n)
        self.work = np.zeros(1)
        self.wa = np.zeros((n, 3))
        self.wb = np.zeros((n, 3))
        self.string_force = np.zeros((n, 3))

    def step(self, poses: np.ndarray, cpg_out: np.ndarray, dt: float, motor_mode: int) -> int:
        return string_step(poses, (self.body_a, self.body_b, self.anchor_a, self.anchor_b), self.params,
                           self.state, cpg_out, dt, motor_mode, (self.force, self.torque, self.tension,
                                                                 self.work, self.wa, self.wb, self.string_force))
