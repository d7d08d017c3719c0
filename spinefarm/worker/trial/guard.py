"""The guard check's fast path: one compiled pass that says a world is clearly sane, so the exact check
(worker.trial.episode.check_state, a dozen numpy calls every 10 ms of every world) runs only near a limit.

`clearly_sane` is True only when every guard passes with a relative margin of MARGIN, which covers the last-bit
differences between its loops and numpy's reductions; anywhere else (a non-finite pose, a limit within the margin,
a segment off the terrain's boxes) it is False and the exact check decides and words the reason. So a trial's
decisions, and its bits, are those of the exact check alone (tests/worker_tests/test_guard.py).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from spinefarm.robot.scene import Terrain
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.trial.scoring import CM

MARGIN = 1e-9


@njit(cache=True)
def clearly_sane(poses: np.ndarray, last: np.ndarray, masses: np.ndarray, lprev: np.ndarray, base_len_cm: np.ndarray,
                 interval_s: float, boxes: np.ndarray, limits: np.ndarray) -> bool:
    """poses (nb, 7); last (nb, 3) positions at the previous check; masses (nb,) kg; lprev (n,) string lengths
    cm; base_len_cm (n,) the stretch guard's base lengths; boxes (k, 5) the terrain's level boxes (centre x, z,
    half extents x, z, top y, cm); limits (speed m/s, kinetic energy J, least and greatest height m, stretch)."""
    kinetic = 0.0
    for b in range(poses.shape[0]):
        for c in range(7):
            if not np.isfinite(poses[b, c]):
                return False
        s2 = 0.0
        for c in range(3):
            v = (poses[b, c] - last[b, c]) / interval_s * CM
            s2 += v * v
        if math.sqrt(s2) >= limits[0] * (1.0 - MARGIN):
            return False
        kinetic += 0.5 * masses[b] * s2
        surface = -np.inf
        for k in range(boxes.shape[0]):
            if abs(poses[b, 0] - boxes[k, 0]) <= boxes[k, 2] and abs(poses[b, 2] - boxes[k, 1]) <= boxes[k, 3]:
                surface = max(surface, boxes[k, 4])
        if not np.isfinite(surface):
            return False
        y_m = (poses[b, 1] - surface) * CM
        if y_m <= limits[2] + MARGIN * max(1.0, abs(limits[2])) or y_m >= limits[3] * (1.0 - MARGIN):
            return False
    if kinetic >= limits[1] * (1.0 - MARGIN):
        return False
    worst = 0.0
    for i in range(lprev.shape[0]):
        worst = max(worst, lprev[i] / base_len_cm[i])
    return worst < limits[4] * (1.0 - MARGIN)


@njit(cache=True)
def check_clear(poses: np.ndarray, last: np.ndarray, last_good: np.ndarray, masses: np.ndarray, mass_total: float,
                string_state: np.ndarray, lprev_column: int, base_len_cm: np.ndarray, interval_s: float,
                boxes: np.ndarray, limits: np.ndarray, com_out: np.ndarray) -> bool:
    """clearly_sane on string_state[:, lprev_column], and where it holds the check's bookkeeping in the same
    call, so a sane check runs no Python per body: com_out = the robot's COM (the bits of
    scoring.robot_com_cm: rows summed in order, then over mass_total = masses.sum()), last = the positions,
    last_good = poses. Where it does not hold nothing is written and the exact check decides."""
    if not clearly_sane(poses, last, masses, string_state[:, lprev_column], base_len_cm, interval_s, boxes, limits):
        return False
    for c in range(3):
        com_out[c] = poses[0, c] * masses[0]
    for b in range(1, poses.shape[0]):
        for c in range(3):
            com_out[c] += poses[b, c] * masses[b]
    for c in range(3):
        com_out[c] /= mass_total
    for b in range(poses.shape[0]):
        for c in range(3):
            last[b, c] = poses[b, c]
        for c in range(7):
            last_good[b, c] = poses[b, c]
    return True


def level_boxes(terrain: Terrain) -> np.ndarray | None:
    """The terrain's boxes as clearly_sane takes them, or None when it has a heightfield or a tilted box (the
    exact check then runs every time)."""
    if terrain.heightfield is not None:
        return None
    rows = []
    for box in terrain.boxes:
        qx, _, _, qw = box.quaternion
        if abs(2 * math.atan2(qx, qw)) > 1e-12:
            return None
        (cx, cy, cz), (hx, hy, hz) = box.centre_cm, box.half_extents_cm
        rows.append((cx, cz, hx, hz, cy + hy))
    return np.array(rows, dtype=np.float64).reshape(-1, 5)


def limits(cfg: TrialConfig) -> np.ndarray:
    return np.array([cfg.max_body_speed_m_s, cfg.max_kinetic_energy_j, cfg.min_height_m, cfg.max_height_m,
                     cfg.max_stretch_ratio], dtype=np.float64)
