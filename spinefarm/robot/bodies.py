"""From a StructureSpec to rigid bodies and string anchors: pure geometry, no engine.

Each segment is one compound rigid body (NTRT auto-compounds rods that share nodes).
Mass is the sum of solid-cylinder masses, the COM their mass-weighted midpoint, and the
inertia NTRT's box approximation: m/12 * (ly^2+lz^2, ...) of the axis-aligned box that holds
every rod's oriented box (spec section 2). Body frames have world-aligned axes at build time.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from spinefarm.robot import fixedmath as fm
from spinefarm.robot.morphology.structure import StructureSpec, rotation_from_y

Quaternion = tuple[float, float, float, float]  # x, y, z, w (pybullet's order)


def quaternion_matrix(q_xyzw: Sequence[float] | np.ndarray) -> np.ndarray:
    """(3, 3) rotation matrix of a unit quaternion (x, y, z, w)."""
    x, y, z, w = q_xyzw
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


@dataclass(frozen=True)
class RodGeometry:
    """One cylinder in its body frame: centre (3,) cm, rotation (3, 3) taking +Y to its axis."""

    centre_cm: np.ndarray
    rotation: np.ndarray
    length_cm: float
    radius_cm: float


@dataclass(frozen=True)
class BodyModel:
    """One rigid segment. com_cm is its world COM at build time; rods are in the body frame."""

    index: int
    mass_kg: float
    com_cm: np.ndarray
    inertia_kg_cm2: np.ndarray
    rods: tuple[RodGeometry, ...]
    friction: float
    rolling_friction: float
    restitution: float


@dataclass(frozen=True)
class StringGeometry:
    """Anchors of every string in its bodies' frames, and their start lengths.

    body_a, body_b: (n_strings,) int; anchor_a_cm, anchor_b_cm: (n_strings, 3) cm in body frames;
    start_length_cm: (n_strings,) anchor-to-anchor distance in the build pose.
    """

    body_a: np.ndarray
    body_b: np.ndarray
    anchor_a_cm: np.ndarray
    anchor_b_cm: np.ndarray
    start_length_cm: np.ndarray


def build_bodies(spec: StructureSpec) -> list[BodyModel]:
    nodes = spec.node_array()
    bodies = []
    for seg in range(spec.n_segments):
        rods = [r for r in spec.rods if spec.node_segment[r.a] == seg]
        masses, mids, geoms, lo, hi = [], [], [], [], []
        for rod in rods:
            mat = spec.rod_material(rod.tag)
            a, b = nodes[rod.a], nodes[rod.b]
            length = fm.norm(b - a)
            masses.append(np.pi * mat.radius_cm**2 * length * mat.density_kg_per_cm3)
            mid = 0.5 * (a + b)
            mids.append(mid)
            rot = rotation_from_y(b - a)
            half = fm.matvec(np.abs(rot), np.array([mat.radius_cm, length / 2, mat.radius_cm]))
            lo.append(mid - half)
            hi.append(mid + half)
            geoms.append((mid, rot, length, mat.radius_cm))
        m = np.array(masses)
        mass = float(m.sum())
        com = (m[:, None] * np.array(mids)).sum(axis=0) / mass
        ext = np.max(hi, axis=0) - np.min(lo, axis=0)
        inertia = mass / 12.0 * np.array([ext[1] ** 2 + ext[2] ** 2, ext[0] ** 2 + ext[2] ** 2,
                                          ext[0] ** 2 + ext[1] ** 2])
        mat0 = spec.rod_material(rods[0].tag)
        bodies.append(BodyModel(
            index=seg, mass_kg=mass, com_cm=com, inertia_kg_cm2=inertia,
            rods=tuple(RodGeometry(mid - com, rot, length, r) for mid, rot, length, r in geoms),
            friction=mat0.friction, rolling_friction=mat0.rolling_friction, restitution=mat0.restitution,
        ))
    return bodies


def _holding_rod(spec: StructureSpec, node: int, nodes: np.ndarray) -> tuple[np.ndarray, float]:
    """Axis and radius of the rod holding `node`: the one with the closest midpoint (ties: first)."""
    best = None
    for rod in spec.rods:
        if node not in (rod.a, rod.b):
            continue
        a, b = nodes[rod.a], nodes[rod.b]
        dist = fm.norm(0.5 * (a + b) - nodes[node])
        if best is None or dist < best[0] - 1e-6:
            best = (dist, (b - a) / fm.norm(b - a), spec.rod_material(rod.tag).radius_cm)
    if best is None:
        return np.zeros(3), 0.0
    return best[1], best[2]


def anchor_point(spec: StructureSpec, node: int, other: int, nodes: np.ndarray, relocate: bool) -> np.ndarray:
    """World anchor of a string end: on the holding rod's surface, toward the other node (spec 3.1)."""
    p = nodes[node]
    if not relocate:
        return p.copy()
    axis, radius = _holding_rod(spec, node, nodes)
    d = nodes[other] - p
    perp = d - fm.dot(d, axis) * axis
    norm = fm.norm(perp)
    if radius == 0.0 or norm < 1e-12:
        return p.copy()
    return p + radius * perp / norm


def build_strings(spec: StructureSpec, bodies: list[BodyModel], relocate_anchors: bool = True) -> StringGeometry:
    nodes = spec.node_array()
    n = len(spec.strings)
    body_a = np.empty(n, dtype=np.int64)
    body_b = np.empty(n, dtype=np.int64)
    anc_a = np.empty((n, 3))
    anc_b = np.empty((n, 3))
    start = np.empty(n)
    for i, s in enumerate(spec.strings):
        wa = anchor_point(spec, s.a, s.b, nodes, relocate_anchors)
        wb = anchor_point(spec, s.b, s.a, nodes, relocate_anchors)
        body_a[i] = spec.node_segment[s.a]
        body_b[i] = spec.node_segment[s.b]
        anc_a[i] = wa - bodies[body_a[i]].com_cm
        anc_b[i] = wb - bodies[body_b[i]].com_cm
        start[i] = fm.norm(wb - wa)
    return StringGeometry(body_a, body_b, anc_a, anc_b, start)


def lowest_rod_surface_cm(spec: StructureSpec) -> float:
    """Lowest point (y, cm) of any rod's cylinder surface in the build pose."""
    nodes = spec.node_array()
    low = np.inf
    for rod in spec.rods:
        a, b = nodes[rod.a], nodes[rod.b]
        axis = (b - a) / fm.norm(b - a)
        r = spec.rod_material(rod.tag).radius_cm
        drop = r * np.sqrt(max(0.0, 1.0 - axis[1] ** 2))  # rim reach below the end centre
        low = min(low, a[1] - drop, b[1] - drop)
    return float(low)
