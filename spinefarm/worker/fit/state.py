"""A recording's state in the engines' terms, and the error between two motions. Pure numpy.

poses (n, nb, 7): COM cm + quaternion (x, y, z, w), as engines read them; velocities (n, nb, 6): linear cm/s and
angular rad/s, world frame, by finite differences of the recorded poses (central inside, one-sided at the ends).
"""

from __future__ import annotations

import numpy as np

from spinefarm.worker.fit.recording import Recording

CM_PER_M = 100.0


def engine_poses(rec: Recording) -> np.ndarray:
    """(n, nb, 7) COM cm + quaternion (x, y, z, w), each quaternion's sign kept continuous over time."""
    q = _continuous(rec.quat_wxyz)
    return np.concatenate([rec.position_m * CM_PER_M, q[:, :, 1:], q[:, :, :1]], axis=2)


def _continuous(q: np.ndarray) -> np.ndarray:
    """q and -q are one rotation: flip signs so that neighbouring samples agree (for differences)."""
    out = q.copy()
    for i in range(1, len(out)):
        flip = np.einsum("bi,bi->b", out[i], out[i - 1]) < 0
        out[i, flip] *= -1.0
    return out


def velocities(rec: Recording) -> np.ndarray:
    """(n, nb, 6) world-frame linear (cm/s) and angular (rad/s) velocity: omega = 2 vec(dq/dt conj(q))."""
    t = rec.time_s
    linear = np.gradient(rec.position_m * CM_PER_M, t, axis=0)
    q = _continuous(rec.quat_wxyz)
    dq = np.gradient(q, t, axis=0)
    w, v = q[..., :1], -q[..., 1:]  # conj(q) = (w, -v)
    dw, dv = dq[..., :1], dq[..., 1:]
    angular = 2.0 * (dw * v + w * dv + np.cross(dv, v))  # vector part of dq * conj(q)
    return np.concatenate([linear, angular], axis=2)


def rest_lengths_cm(rec: Recording, times_s: np.ndarray) -> np.ndarray:
    """(len(times_s), n_strings) the recorded rest lengths (cm) at these times, linearly interpolated."""
    rest = rec.rest_length_m * CM_PER_M
    return np.stack([np.interp(times_s, rec.time_s, rest[:, i]) for i in range(rest.shape[1])], axis=1)


def pose_error(sim: np.ndarray, rec: np.ndarray, length_cm: float) -> np.ndarray:
    """Per sample and segment (..., nb): sqrt(position error^2 + (length_cm * rotation angle)^2) in cm, both poses
    (..., nb, 7) COM cm + quaternion (x, y, z, w); length_cm weighs a rotation as the arc it sweeps at that
    radius (a segment's size)."""
    d = np.linalg.norm(sim[..., :3] - rec[..., :3], axis=-1)
    return np.sqrt(d**2 + (length_cm * rotation_angle(sim, rec)) ** 2)


def rotation_angle(sim: np.ndarray, rec: np.ndarray) -> np.ndarray:
    """Per sample and segment (..., nb): the angle (rad) turning one orientation into the other, poses (..., nb, 7)
    with the quaternion (x, y, z, w) last (q and -q are one orientation)."""
    dot = np.clip(np.abs(np.einsum("...i,...i->...", sim[..., 3:], rec[..., 3:])), 0.0, 1.0)
    return 2.0 * np.arccos(dot)


def planar_distance_cm(a: np.ndarray, b: np.ndarray) -> float:
    """Horizontal (XZ) distance between two points (3,) cm, as NTRT scores."""
    return float(np.hypot(b[0] - a[0], b[2] - a[2]))
