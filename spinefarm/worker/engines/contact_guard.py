"""Segment-segment contacts only where a trial needs them.

Segment-segment collision tests are most of a MuJoCo step on a spine (neighbouring segments' bounding
boxes interleave, so every step runs their capsule-pair tests), and in the gaits measured such contacts
hardly ever form. With `segment_contacts="auto"` the model leaves them out and this guard watches the
gaps instead: at each look it measures the smallest gap between the capsules of every segment pair the
scene lets collide. While every gap stays larger than the distance the segments could close before the
next look (from their current speeds, with a factor of two to spare), no contact can have formed, and
the trial is the same bits as one with the contacts modelled. The guard says how many steps are safe (up
to the trial's next check, fewer when a gap could close sooner), and the trial loop looks again after
them. Only when a gap could
close within a single step is the trial run again from the start with the contacts (worker.trial.simulation).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from spinefarm.robot import fixedmath as fm
from spinefarm.robot.bodies import BodyModel

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
    """Shortest distance between segments p1-q1 and p2-q2 (closest points, clamped to both); scalar
    arithmetic only, so no temporary arrays are made in the guard's inner loop."""
    d1x, d1y, d1z = q1[0] - p1[0], q1[1] - p1[1], q1[2] - p1[2]
    d2x, d2y, d2z = q2[0] - p2[0], q2[1] - p2[1], q2[2] - p2[2]
    rx, ry, rz = p1[0] - p2[0], p1[1] - p2[1], p1[2] - p2[2]
    a = d1x * d1x + d1y * d1y + d1z * d1z
    e = d2x * d2x + d2y * d2y + d2z * d2z
    f = d2x * rx + d2y * ry + d2z * rz
    eps = 1e-12
    if a <= eps and e <= eps:
        s = 0.0
        t = 0.0
    elif a <= eps:
        s = 0.0
        t = min(max(f / e, 0.0), 1.0)
    else:
        c = d1x * rx + d1y * ry + d1z * rz
        if e <= eps:
            t = 0.0
            s = min(max(-c / a, 0.0), 1.0)
        else:
            b = d1x * d2x + d1y * d2y + d1z * d2z
            denom = a * e - b * b
            s = min(max((b * f - c * e) / denom, 0.0), 1.0) if denom > eps else 0.0
            t = (b * s + f) / e
            if t < 0.0:
                t = 0.0
                s = min(max(-c / a, 0.0), 1.0)
            elif t > 1.0:
                t = 1.0
                s = min(max((b - c) / a, 0.0), 1.0)
    x = rx + d1x * s - d2x * t
    y = ry + d1y * s - d2y * t
    z = rz + d1z * s - d2z * t
    return math.sqrt(x * x + y * y + z * z)


@njit(cache=True)
def contact_free_time(qpos, qvel, horizon_s, capsules, pairs, scratch):
    """(t, gap): no two segments can touch for t seconds (at most horizon_s), and the gap (cm) of the pair
    that limits it (inf if none does). capsules = (cap_start (nb+1,), cap_p0, cap_p1 (c, 3) body frame,
    cap_radius, cap_reach (c,), body_radius (nb,)); pairs = (pair_a, pair_b) (p,); scratch = world ends
    (c, 3) twice. A pair's t is (gap - MIN_CLEARANCE_CM) / (SAFETY_FACTOR * v), with v
    the largest relative speed of two of their points, |v_a - v_b| + |w_a| r_a + |w_b| r_b (r the bounding
    radii). Body pairs and capsule pairs whose bounding spheres alone give a longer t than the shortest
    found so far are skipped without a segment-segment distance."""
    cap_start, cap_p0, cap_p1, cap_radius, cap_reach, body_radius = capsules
    pair_a, pair_b = pairs
    world0, world1 = scratch
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
    t_free, limiting_gap = horizon_s, np.inf
    for i in range(pair_a.shape[0]):
        a, b = pair_a[i], pair_b[i]
        vx = qvel[a, 0] - qvel[b, 0]
        vy = qvel[a, 1] - qvel[b, 1]
        vz = qvel[a, 2] - qvel[b, 2]
        closing = SAFETY_FACTOR * (math.sqrt(vx * vx + vy * vy + vz * vz) + spin[a] + spin[b])
        reach = closing * t_free + MIN_CLEARANCE_CM  # a gap wider than this cannot shorten t_free
        dx = qpos[a, 0] - qpos[b, 0]
        dy = qpos[a, 1] - qpos[b, 1]
        dz = qpos[a, 2] - qpos[b, 2]
        if math.sqrt(dx * dx + dy * dy + dz * dz) - body_radius[a] - body_radius[b] > reach:
            continue
        for ca in range(cap_start[a], cap_start[a + 1]):
            for cb in range(cap_start[b], cap_start[b + 1]):
                mx = 0.5 * (world0[ca, 0] + world1[ca, 0] - world0[cb, 0] - world1[cb, 0])
                my = 0.5 * (world0[ca, 1] + world1[ca, 1] - world0[cb, 1] - world1[cb, 1])
                mz = 0.5 * (world0[ca, 2] + world1[ca, 2] - world0[cb, 2] - world1[cb, 2])
                if math.sqrt(mx * mx + my * my + mz * mz) - cap_reach[ca] - cap_reach[cb] > reach:
                    continue  # capsule bounding spheres apart
                gap = _segment_distance(world0[ca], world1[ca], world0[cb], world1[cb]) - cap_radius[ca] \
                    - cap_radius[cb]
                if gap <= reach:
                    t_free = max(0.0, gap - MIN_CLEARANCE_CM) / closing if closing > 0.0 else \
                        (0.0 if gap <= MIN_CLEARANCE_CM else t_free)
                    limiting_gap = gap
                    reach = closing * t_free + MIN_CLEARANCE_CM
    return t_free, limiting_gap


class SegmentContactGuard:
    """Capsules of every segment (body frame, about the COM) and the segment pairs the scene lets
    collide; `free_time_s(qpos, qvel, horizon_s)` says for how long no contact can form (qpos (nb, 7)
    x y z w x y z, qvel (nb, 6) as MuJoCo's free joints hold them)."""

    def __init__(self, bodies: list[BodyModel], excluded: list[tuple[int, int]]) -> None:
        p0, p1, radius, start = [], [], [], [0]
        body_radius = np.zeros(len(bodies))
        for i, body in enumerate(bodies):
            for rod in body.rods:
                half = rod.rotation[:, 1] * (rod.length_cm / 2)
                p0.append(rod.centre_cm - half)
                p1.append(rod.centre_cm + half)
                radius.append(rod.radius_cm)
                body_radius[i] = max(body_radius[i], fm.norm(p0[-1]) + rod.radius_cm,
                                     fm.norm(p1[-1]) + rod.radius_cm)
            start.append(len(p0))
        off = set(excluded)
        pairs = [(a, b) for a in range(len(bodies)) for b in range(a + 1, len(bodies))
                 if (a, b) not in off and (b, a) not in off]
        self.cap_start = np.array(start, dtype=np.int64)
        self.cap_p0 = np.array(p0, dtype=float).reshape(-1, 3)
        self.cap_p1 = np.array(p1, dtype=float).reshape(-1, 3)
        self.cap_radius = np.array(radius, dtype=float)
        # bounding sphere of each capsule about its midpoint: half its length plus its radius
        self.cap_reach = 0.5 * fm.norm(self.cap_p1 - self.cap_p0) + self.cap_radius
        self.body_radius = body_radius
        self.pair_a = np.array([a for a, _ in pairs], dtype=np.int64)
        self.pair_b = np.array([b for _, b in pairs], dtype=np.int64)
        self._w0 = np.zeros_like(self.cap_p0)
        self._w1 = np.zeros_like(self.cap_p1)
        # the compiled call's arguments, built once (a look comes every check of every world)
        self.kernel_args = ((self.cap_start, self.cap_p0, self.cap_p1, self.cap_radius, self.cap_reach,
                              self.body_radius), (self.pair_a, self.pair_b), (self._w0, self._w1))

    def free_time_s(self, qpos: np.ndarray, qvel: np.ndarray, horizon_s: float) -> tuple[float, float]:
        """(seconds, at most horizon_s, during which no two segments can touch; the gap in cm of the pair
        that limits it, inf if none does): see contact_free_time."""
        if self.pair_a.size == 0:
            return horizon_s, math.inf
        return contact_free_time(qpos, qvel, horizon_s, *self.kernel_args)
