"""Pure scoring functions of recorded positions and work (never reads the engine)."""

from __future__ import annotations

import math

import numpy as np

G_M_S2 = 9.81
CM = 0.01
WORK_J_PER_INTERNAL = 1e-4  # kg*cm^2/s^2 -> J


def planar_distance_cm(start_cm: np.ndarray, end_cm: np.ndarray) -> float:
    """Displacement in the ground plane (x, z), Y being up (spec 5)."""
    d = np.asarray(end_cm, dtype=float) - np.asarray(start_cm, dtype=float)
    return float(math.hypot(d[0], d[2]))


def robot_com_cm(positions_cm: np.ndarray, masses_kg: np.ndarray) -> np.ndarray:
    """Mass-weighted centre of (n_bodies, 3) positions."""
    m = np.asarray(masses_kg, dtype=float)
    return (np.asarray(positions_cm)[:, :3] * m[:, None]).sum(axis=0) / m.sum()


def cost_of_transport(work_j: float, mass_kg: float, distance_m: float) -> float:
    """COT = W / (m g d), dimensionless; infinite when the robot did not move."""
    if distance_m <= 0.0 or not math.isfinite(distance_m):
        return math.inf
    return work_j / (mass_kg * G_M_S2 * distance_m)


def rms_path_error_cm(path_cm: np.ndarray, time_s: np.ndarray, reference_cm: np.ndarray,
                      reference_time_s: np.ndarray) -> float:
    """RMS distance between two (n, 3) centre-of-mass paths, the first interpolated onto the
    reference's times (over the time both cover)."""
    a = np.asarray(path_cm, dtype=float)
    b = np.asarray(reference_cm, dtype=float)
    t_end = min(float(time_s[-1]), float(reference_time_s[-1]))
    keep = np.asarray(reference_time_s) <= t_end + 1e-12
    if len(a) < 2 or not keep.any():
        return math.nan
    t = np.asarray(reference_time_s)[keep]
    interp = np.column_stack([np.interp(t, time_s, a[:, c]) for c in range(3)])
    return float(np.sqrt(np.mean(np.sum((interp - b[keep]) ** 2, axis=1))))
