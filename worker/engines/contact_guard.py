"""Segment-segment contacts only where a trial needs them.

Segment-segment collision tests are most of a MuJoCo step on a spine (neighbouring segments' bounding
boxes interleave, so every step runs their capsule-pair tests), and in the gaits measured no such
contact ever forms. With `segment_contacts="auto"` the model leaves them out and this guard watches
the gaps instead: at each of the trial's checks it measures the smallest gap between the capsules of
every segment pair the scene lets collide. While every gap stays larger than the distance the segments
could close before the next check (from their current speeds, with a factor of two to spare), no
contact can have formed, and the trial is the same bits as one with the contacts modelled; otherwise
the trial is run again from the start with them (worker.trial).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from robot.bodies import BodyModel

SAFETY_FACTOR = 2.0
MIN_CLEARANCE_CM = 0.1


@njit(cache=True)
def _rotate(q, v, out):
    """out = R(q) v for a MuJoCo quaternion q = (w, x, y, z)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    tx = 2.0 * (y * v[2] - z * v[1])
    ty = 2.0 * (z * v[0] - x * v[2])
    tz = 2.0 * (x * v[1] - y * v[0])
    out[0] = v[0] + w * tx + (y * tz - z * ty)
    out[1] = v[1] + w * ty + (z * tx - x * tz)
    out[2] = v[2] + w * tz + (x * ty - y * tx)


@njit(cache=True)
def _segment_distance(p1, q1, p2, q2) -> float:
    """Shortest distance between segments p1-q1 and p2-q2 (closest points, clamped to both)."""
    d1 = q1 - p1
    d2 = q2 - p2
    r = p1 - p2
    a = d1 @ d1
    e = d2 @ d2
    f = d2 @ r
    eps = 1e-12
    if a <= eps and e <= eps:
        s = 0.0
        t = 0.0
    elif a <= eps:
        s = 0.0
        t = min(max(f / e, 0.0), 1.0)
    else:
        c = d1 @ r
        if e <= eps:
            t = 0.0
            s = min(max(-c / a, 0.0), 1.0)
        else:
            b = d1 @ d2
            denom = a * e - b * b
            s = min(max((b * f - c * e) / denom, 0.0), 1.0) if denom > eps else 0.0
            t = (b * s + f) / e
            if t < 0.0:
                t = 0.0
                s = min(max(-c / a, 0.0), 1.0)
            elif t > 1.0:
                t = 1.0
                s = min(max((b - c) / a, 0.0), 1.0)
    diff = (p1 + d1 * s) - (p2 + d2 * t)
    return math.sqrt(diff @ diff)


@njit(cache=True)
def closest_approach(qpos, qvel, interval_s, cap_start, cap_p0, cap_p1, cap_radius, body_radius, pair_a, pair_b,
                     world0, world1):
    """(slack, gap, reach) of the tightest listed body pair: gap, the smallest surface gap (cm) between
    their capsules; reach, how far they could close within interval_s: SAFETY_FACTOR times the largest
    relative speed of two of their points, |v_a - v_b| + |w_a| r_a + |w_b| r_b with r the bounding
    radii, plus MIN_CLEARANCE_CM; slack = gap - reach.
    Pairs whose bounding spheres are further apart than their reach plus the tightest slack so far are
    skipped."""
    nb = qpos.shape[0]
    spin = np.empty(nb)
    for b in range(nb):
        spin[b] = math.sqrt(qvel[b, 3] ** 2 + qvel[b, 4] ** 2 + qvel[b, 5] ** 2) * body_radius[b]
        for c in range(cap_start[b], cap_start[b + 1]):
            _rotate(qpos[b, 3:7], cap_p0[c], world0[c])
            _rotate(qpos[b, 3:7], cap_p1[c], world1[c])
            for k in range(3):
                world0[c, k] += qpos[b, k]
                world1[c, k] += qpos[b, k]
    best, best_gap, best_reach = np.inf, np.inf, 0.0
    for i in range(pair_a.shape[0]):
        a, b = pair_a[i], pair_b[i]
        vx = qvel[a, 0] - qvel[b, 0]
        vy = qvel[a, 1] - qvel[b, 1]
        vz = qvel[a, 2] - qvel[b, 2]
        closing = math.sqrt(vx * vx + vy * vy + vz * vz) + spin[a] + spin[b]
        reach = SAFETY_FACTOR * closing * interval_s + MIN_CLEARANCE_CM
        dx = qpos[a, 0] - qpos[b, 0]
        dy = qpos[a, 1] - qpos[b, 1]
        dz = qpos[a, 2] - qpos[b, 2]
        if math.sqrt(dx * dx + dy * dy + dz * dz) - body_radius[a] - body_radius[b] - reach > best:
            continue
        for ca in range(cap_start[a], cap_start[a + 1]):
            for cb in range(cap_start[b], cap_start[b + 1]):
                gap = _segment_distance(world0[ca], world1[ca], world0[cb], world1[cb]) - cap_radius[ca] \
                    - cap_radius[cb]
                if gap - reach < best:
                    best, best_gap, best_reach = gap - reach, gap, reach
    return best, best_gap, best_reach


class SegmentContactGuard:
    """Capsules of every segment (body frame, about the COM) and the segment pairs the scene lets
    collide; `gap_too_small(qpos, qvel, interval_s)` says whether a contact could form before the next
    check (qpos (nb, 7) x y z w x y z, qvel (nb, 6) as MuJoCo's free joints hold them)."""

    def __init__(self, bodies: list[BodyModel], excluded: list[tuple[int, int]]) -> None:
        p0, p1, radius, start = [], [], [], [0]
        body_radius = np.zeros(len(bodies))
        for i, body in enumerate(bodies):
            for rod in body.rods:
                half = rod.rotation[:, 1] * (rod.length_cm / 2)
                p0.append(rod.centre_cm - half)
                p1.append(rod.centre_cm + half)
                radius.append(rod.radius_cm)
                body_radius[i] = max(body_radius[i], float(np.linalg.norm(p0[-1])) + rod.radius_cm,
                                     float(np.linalg.norm(p1[-1])) + rod.radius_cm)
            start.append(len(p0))
        off = set(excluded)
        pairs = [(a, b) for a in range(len(bodies)) for b in range(a + 1, len(bodies))
                 if (a, b) not in off and (b, a) not in off]
        self.cap_start = np.array(start, dtype=np.int64)
        self.cap_p0 = np.array(p0, dtype=float).reshape(-1, 3)
        self.cap_p1 = np.array(p1, dtype=float).reshape(-1, 3)
        self.cap_radius = np.array(radius, dtype=float)
        self.body_radius = body_radius
        self.pair_a = np.array([a for a, _ in pairs], dtype=np.int64)
        self.pair_b = np.array([b for _, b in pairs], dtype=np.int64)
        self._w0 = np.zeros_like(self.cap_p0)
        self._w1 = np.zeros_like(self.cap_p1)

    def gap_and_reach_cm(self, qpos: np.ndarray, qvel: np.ndarray, interval_s: float) -> tuple[float, float]:
        """(gap, reach) of the segment pair closest to touching within interval_s (see closest_approach);
        no contact can form before the next check while gap > reach."""
        if self.pair_a.size == 0:
            return math.inf, 0.0
        _, gap, reach = closest_approach(qpos, qvel, interval_s, self.cap_start, self.cap_p0, self.cap_p1,
                                         self.cap_radius, self.body_radius, self.pair_a, self.pair_b, self._w0,
                                         self._w1)
        return gap, reach
