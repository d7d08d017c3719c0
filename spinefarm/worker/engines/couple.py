"""A net wrench as two forces, for engines whose torque input is unreliable (pybullet's
applyExternalTorque on maximal-coordinate bodies gives wrong angular responses)."""

from __future__ import annotations

import numpy as np
from numba import njit

COUPLE_LEVER_CM = 1.0


@njit(cache=True)
def wrench_to_force_pairs(poses, force, torque, out_points, out_forces):
    """Net force F and torque tau about the COM as two forces F/2 +- Fc at COM +- s u, u perpendicular
    to tau and Fc = (tau x u) / (2 s): they sum to F and their moment is u x (tau x u) = tau."""
    s = COUPLE_LEVER_CM
    for b in range(poses.shape[0]):
        tx, ty, tz = torque[b, 0], torque[b, 1], torque[b, 2]
        ax, ay, az = abs(tx), abs(ty), abs(tz)
        if ax <= ay and ax <= az:
            ex, ey, ez = 1.0, 0.0, 0.0
        elif ay <= az:
            ex, ey, ez = 0.0, 1.0, 0.0
        else:
            ex, ey, ez = 0.0, 0.0, 1.0
        ux = ty * ez - tz * ey
        uy = tz * ex - tx * ez
        uz = tx * ey - ty * ex
        norm = np.sqrt(ux * ux + uy * uy + uz * uz)
        if norm > 0.0:
            ux, uy, uz = ux / norm, uy / norm, uz / norm
        else:
            ux, uy, uz = 1.0, 0.0, 0.0
        cx = (ty * uz - tz * uy) / (2.0 * s)
        cy = (tz * ux - tx * uz) / (2.0 * s)
        cz = (tx * uy - ty * ux) / (2.0 * s)
        i0 = 2 * b
        i1 = 2 * b + 1
        out_points[i0, 0] = poses[b, 0] + s * ux
        out_points[i0, 1] = poses[b, 1] + s * uy
        out_points[i0, 2] = poses[b, 2] + s * uz
        out_points[i1, 0] = poses[b, 0] - s * ux
        out_points[i1, 1] = poses[b, 1] - s * uy
        out_points[i1, 2] = poses[b, 2] - s * uz
        out_forces[i0, 0] = 0.5 * force[b, 0] + cx
        out_forces[i0, 1] = 0.5 * force[b, 1] + cy
        out_forces[i0, 2] = 0.5 * force[b, 2] + cz
        out_forces[i1, 0] = 0.5 * force[b, 0] - cx
        out_forces[i1, 1] = 0.5 * force[b, 1] - cy
        out_forces[i1, 2] = 0.5 * force[b, 2] - cz
