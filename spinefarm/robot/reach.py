"""Which rods of different segments can come within reach of each other, from the structure alone.

Pure geometry (no engine). Segments are rigid; strings are tension-only, so a string bounds how far apart its
two anchors can get (its reach length), never how near. A chain of strings and rigid segments bounds the
distance between any two anchors: the shortest path over a graph whose vertices are the string anchors and
whose edges are strings (their reach length) and pairs of anchors on one segment (their fixed distance).

For rods ra on segment A and rb on segment B, with anchors p on A and q on B at most D(p, q) apart, every point
y of rb is within D(p, q) + max|y - q| of p, so every point x of ra is at least
    dist(ra, p) - D(p, q) - maxdist(rb, q)
from every point of rb (and the same with the roles swapped). The largest of these over all anchor pairs,
less both radii, is a lower bound on the pair's surface gap; a pair whose bound exceeds the margin can never
touch. Segments not joined by any chain of strings are unbounded: all their rod pairs stay.

A string's reach length is its start length plus the stretch at which it pulls with its maximum tension
(max_tension / stiffness): the motor pays out rest length rather than pull harder, so a string longer than
that is one the robot's own loads (its weight, its strings) would have to tear open. It is an engineering
bound, not a proof; a backend that leaves the other pairs out may watch them (worker.engines.contact_guard).
"""

from __future__ import annotations

import numpy as np

from spinefarm.robot.bodies import BodyModel, StringGeometry
from spinefarm.robot.morphology.structure import StructureSpec

REACH_MARGIN_CM = 1.0  # kept on top of the bound: a pair this close may still be modelled


def string_reach_lengths_cm(spec: StructureSpec, geom: StringGeometry) -> np.ndarray:
    """(n_strings,) cm: the longest each string gets, start length plus its stretch at maximum tension."""
    stretch_cm = np.array([100.0 * m.max_tension_n / m.stiffness_n_per_m
                           for m in (spec.string_material(s.tag) for s in spec.strings)])
    return np.asarray(geom.start_length_cm, dtype=float) + stretch_cm


def anchor_distances_cm(geom: StringGeometry, reach_cm: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(anchor body (n,), anchor point in its body's frame (n, 3) cm, D (n, n) cm): every string end is an
    anchor (n = 2 n_strings); D bounds how far apart two anchors can be (inf: no chain joins them)."""
    body = np.concatenate([geom.body_a, geom.body_b]).astype(np.int64)
    point = np.concatenate([geom.anchor_a_cm, geom.anchor_b_cm]).astype(float).reshape(-1, 3)
    n_strings = len(reach_cm)
    d = np.full((len(body), len(body)), np.inf)
    same = body[:, None] == body[None, :]
    rigid = np.sqrt(((point[:, None, :] - point[None, :, :]) ** 2).sum(axis=2))
    d[same] = rigid[same]
    ends = np.arange(n_strings)
    d[ends, ends + n_strings] = np.minimum(d[ends, ends + n_strings], reach_cm)
    d[ends + n_strings, ends] = d[ends, ends + n_strings]
    for k in range(len(body)):  # Floyd-Warshall, one whole-matrix update per intermediate anchor
        np.minimum(d, d[:, k:k + 1] + d[k:k + 1, :], out=d)
    return body, point, d


def _rod_ends(bodies: list[BodyModel]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(body (r,), rod index in its body (r,), ends (r, 2, 3) cm in the body frame, radius (r,) cm)."""
    owner, index, ends, radius = [], [], [], []
    for b, body in enumerate(bodies):
        for j, rod in enumerate(body.rods):
            half = rod.rotation[:, 1] * (rod.length_cm / 2)
            owner.append(b)
            index.append(j)
            ends.append((rod.centre_cm - half, rod.centre_cm + half))
            radius.append(rod.radius_cm)
    return (np.array(owner, dtype=np.int64), np.array(index, dtype=np.int64),
            np.array(ends, dtype=float).reshape(-1, 2, 3), np.array(radius, dtype=float))


def _point_segment_cm(ends: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(nearest, farthest) distance (r, n) cm from each point (n, 3) to each segment (r, 2, 3)."""
    p0, axis = ends[:, 0, :], ends[:, 1, :] - ends[:, 0, :]
    rel = points[None, :, :] - p0[:, None, :]
    length2 = np.maximum((axis ** 2).sum(axis=1), 1e-300)[:, None]
    t = np.clip((rel * axis[:, None, :]).sum(axis=2) / length2, 0.0, 1.0)
    near = np.sqrt(((rel - t[:, :, None] * axis[:, None, :]) ** 2).sum(axis=2))
    far = np.maximum(np.sqrt((rel ** 2).sum(axis=2)),
                     np.sqrt(((points[None, :, :] - ends[:, 1, None, :]) ** 2).sum(axis=2)))
    return near, far


def rod_gap_bounds_cm(bodies: list[BodyModel], geom: StringGeometry, reach_cm: np.ndarray,
                      body_pairs: list[tuple[int, int]]) -> list[np.ndarray]:
    """Per body pair (a, b): (rods of a, rods of b) cm, a lower bound on each rod pair's surface gap
    (-inf where no chain of strings joins a and b)."""
    anchor_body, anchor_point, d = anchor_distances_cm(geom, reach_cm)
    owner, _, ends, radius = _rod_ends(bodies)
    near, far = _point_segment_cm(ends, anchor_point)  # (rods, anchors)
    out = []
    for a, b in body_pairs:
        ra, rb = np.flatnonzero(owner == a), np.flatnonzero(owner == b)
        pa, pb = np.flatnonzero(anchor_body == a), np.flatnonzero(anchor_body == b)
        bound = np.full((len(ra), len(rb)), -np.inf)
        if len(pa) and len(pb):
            dab = d[np.ix_(pa, pb)]  # (anchors of a, anchors of b)
            # x on ra, y on rb: |x - y| >= dist(ra, p) - D(p, q) - maxdist(rb, q), for the best p, q
            via_q = (near[np.ix_(ra, pa)][:, :, None] - dab[None]).max(axis=1)  # (rods of a, anchors of b)
            one = (via_q[:, None, :] - far[np.ix_(rb, pb)][None]).max(axis=2)
            via_p = (near[np.ix_(rb, pb)][:, None, :] - dab[None]).max(axis=2)  # (rods of b, anchors of a)
            two = (via_p[None] - far[np.ix_(ra, pa)][:, None, :]).max(axis=2)
            bound = np.maximum(one, two)
        out.append(bound - radius[ra][:, None] - radius[rb][None, :])
    return out


def reachable_rod_pairs(spec: StructureSpec, bodies: list[BodyModel], geom: StringGeometry,
                        body_pairs: list[tuple[int, int]], margin_cm: float = REACH_MARGIN_CM) -> np.ndarray:
    """(p, 4) int64 rows (body a, rod of a, body b, rod of b), a < b, of the rod pairs among `body_pairs`
    whose surfaces can come within margin_cm of each other (see the module docstring)."""
    reach_cm = string_reach_lengths_cm(spec, geom)
    rows = []
    for (a, b), gap in zip(body_pairs, rod_gap_bounds_cm(bodies, geom, reach_cm, body_pairs), strict=True):
        ia, ib = np.nonzero(gap <= margin_cm)
        rows.extend((a, int(i), b, int(j)) if a < b else (b, int(j), a, int(i)) for i, j in zip(ia, ib, strict=True))
    return np.array(sorted(rows), dtype=np.int64).reshape(-1, 4)
