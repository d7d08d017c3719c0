"""Structure specs: nodes, rods and strings as data with tags, and per-tag physical config.

Internal units are centimetres, kilograms and seconds (NTRT's world, g = 981 cm/s^2), chosen
because Bullet's absolute tolerances (margins 0.04, split-impulse threshold -0.04) are tuned
for objects a few units across. In that unit system a stiffness in N/m and a damping in N*s/m
have the same numbers (kg/s^2, kg/s), and a force of 1 N is 100 kg*cm/s^2.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field

import numpy as np

from spinefarm.protocol.errors import ConfigError, MorphologySpecError, bounded, check_fields
from spinefarm.robot import fixedmath as fm

NEWTON = 100.0  # kg*cm/s^2 per N


@dataclass(frozen=True)
class RodMaterial:
    """Solid cylinders of one tag. Friction is the Bullet coefficient (combined as a product)."""

    radius_cm: float = bounded(0.5, 0.0, low_inclusive=False)
    density_kg_per_cm3: float = bounded(0.014, 0.0, low_inclusive=False)
    friction: float = bounded(0.5, 0.0, 10.0)
    rolling_friction: float = bounded(0.0, 0.0, 10.0)
    restitution: float = bounded(0.0, 0.0, 1.0)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class StringMaterial:
    """Tension-only Hooke strings with linear damping and a rest-length motor (spec 3.2, 3.3).

    pretension_n shortens the initial rest length by pretension/k. drive_offset_cm, when set,
    makes a passive string's motor pull its rest length toward (start length - offset) every
    step (NTRT's octahedral ligaments). motor_radius_cm, when set, makes an impedance-controlled string's
    motor NTRT's current kinematic motor (spec 3.3, 4.3 [H]; motor model ntrt2026 only): a spool of that
    radius with inertia, viscous friction and a torque-speed limit, its torque from a PD on tension
    (gains in cm and cm s per unit of tension error), not back-drivable (tension never lets it out).
    """

    stiffness_n_per_m: float = bounded(1000.0, 0.0, low_inclusive=False)
    damping_n_s_per_m: float = bounded(10.0, 0.0)
    pretension_n: float = bounded(0.0, 0.0)
    max_tension_n: float = bounded(70.0, 0.0, low_inclusive=False)
    motor_speed_cm_s: float = bounded(24.0, 0.0, low_inclusive=False)
    motor_accel_cm_s2: float = bounded(10000.0, 0.0, low_inclusive=False)
    min_rest_length_cm: float = bounded(0.1, 0.0)
    min_actuated_length_cm: float = bounded(0.1, 0.0)
    drive_offset_cm: float | None = bounded(None)
    motor_radius_cm: float | None = bounded(None, 0.0, low_inclusive=False)
    motor_inertia_kg_cm2: float = bounded(1.0, 0.0, low_inclusive=False)
    motor_friction_kg_cm2_s: float = bounded(10.0, 0.0)
    tension_pd_p_cm: float = bounded(5000.0, 0.0)
    tension_pd_d_cm_s: float = bounded(10.0, 0.0)

    def __post_init__(self) -> None:
        check_fields(self)

    def to_dict(self) -> dict:
        """Its fields; without a kinematic motor the motor's own fields are left out (the hashes of specs
        written before it existed stay as they were)."""
        d = asdict(self)
        if self.motor_radius_cm is None:
            for key in KINEMATIC_MOTOR_FIELDS:
                del d[key]
        return d


KINEMATIC_MOTOR_FIELDS = ("motor_radius_cm", "motor_inertia_kg_cm2", "motor_friction_kg_cm2_s", "tension_pd_p_cm",
                          "tension_pd_d_cm_s")


@dataclass(frozen=True)
class Rod:
    a: int
    b: int
    tag: str


@dataclass(frozen=True)
class String:
    """A string from node a (on one body) to node b (on another body)."""

    a: int
    b: int
    tag: str


def _known_ends(kind: str, i: int, pair: Rod | String, n_nodes: int) -> str:
    """How errors name rods[i] or strings[i]; raises when either end is not a node."""
    where = f"{kind}[{i}] ({pair.a}->{pair.b}, tag {pair.tag!r})"
    for end in (pair.a, pair.b):
        if not 0 <= end < n_nodes:
            raise MorphologySpecError(f"{where} names an unknown node", received=end,
                                      expected=f"a node index in [0, {n_nodes - 1}]")
    return where


@dataclass(frozen=True)
class StructureSpec:
    """A tensegrity structure as data. Nodes are in cm, world frame, Y up.

    node_segment[i] is the rigid body (segment) that node i belongs to; every rod joins two nodes
    of one segment, and every segment is one compound rigid body. Hashable and JSON-serialisable.
    """

    name: str
    nodes: tuple[tuple[float, float, float], ...]
    node_segment: tuple[int, ...]
    rods: tuple[Rod, ...]
    strings: tuple[String, ...]
    rod_materials: tuple[tuple[str, RodMaterial], ...]
    string_materials: tuple[tuple[str, StringMaterial], ...]
    node_names: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        self.validate()

    # -- validation -------------------------------------------------------------------------
    def validate(self) -> None:
        n = len(self.nodes)
        if n == 0:
            raise MorphologySpecError(f"structure {self.name!r} has no nodes", expected="at least 4 nodes")
        if len(self.node_segment) != n:
            raise MorphologySpecError("node_segment length differs from node count",
                                      received=len(self.node_segment), expected=n)
        rod_tags = dict(self.rod_materials)
        string_tags = dict(self.string_materials)
        pts = np.asarray(self.nodes, dtype=float)
        if pts.shape != (n, 3) or not np.all(np.isfinite(pts)):
            raise MorphologySpecError("nodes must be finite (x, y, z) triples in cm", received=pts.shape,
                                      expected=f"({n}, 3) finite values")
        for i, rod in enumerate(self.rods):
            where = _known_ends("rods", i, rod, n)
            if self.node_segment[rod.a] != self.node_segment[rod.b]:
                raise MorphologySpecError(f"{where} joins two segments",
                                          received=(self.node_segment[rod.a], self.node_segment[rod.b]),
                                          expected="both ends in one segment (a rigid body)")
            if fm.norm(pts[rod.a] - pts[rod.b]) < 1e-9:
                raise MorphologySpecError(f"{where} has zero length", received=0.0, expected="> 0 cm")
            if rod.tag not in rod_tags:
                raise MorphologySpecError(f"{where} has a tag with no rod config", received=rod.tag,
                                          expected=f"one of {sorted(rod_tags)}")
        segs_with_rods = {self.node_segment[r.a] for r in self.rods}
        for i, s in enumerate(self.strings):
            where = _known_ends("strings", i, s, n)
            if self.node_segment[s.a] == self.node_segment[s.b]:
                raise MorphologySpecError(f"{where} joins a body to itself", received=self.node_segment[s.a],
                                          expected="ends on two different segments")
            if s.tag not in string_tags:
                raise MorphologySpecError(f"{where} has a tag with no string config", received=s.tag,
                                          expected=f"one of {sorted(string_tags)}")
            for end in (s.a, s.b):
                if self.node_segment[end] not in segs_with_rods:
                    raise MorphologySpecError(f"{where} ends on a segment with no rods",
                                              received=self.node_segment[end], expected="a segment with rods")

    # -- derived views ------------------------------------------------------------------------
    @property
    def n_segments(self) -> int:
        return max(self.node_segment) + 1

    def rod_material(self, tag: str) -> RodMaterial:
        return dict(self.rod_materials)[tag]

    def string_material(self, tag: str) -> StringMaterial:
        return dict(self.string_materials)[tag]

    def node_array(self) -> np.ndarray:
        """(n_nodes, 3) cm."""
        return np.asarray(self.nodes, dtype=float)

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "nodes": [list(p) for p in self.nodes],
            "node_segment": list(self.node_segment),
            "node_names": list(self.node_names),
            "rods": [[r.a, r.b, r.tag] for r in self.rods],
            "strings": [[s.a, s.b, s.tag] for s in self.strings],
            "rod_materials": {t: asdict(m) for t, m in self.rod_materials},
            "string_materials": {t: m.to_dict() for t, m in self.string_materials},
        }

    @classmethod
    def from_dict(cls, d: Mapping) -> StructureSpec:
        try:
            return cls(
                name=str(d["name"]),
                nodes=tuple(tuple(float(c) for c in p) for p in d["nodes"]),
                node_segment=tuple(int(s) for s in d["node_segment"]),
                node_names=tuple(d.get("node_names", ())),
                rods=tuple(Rod(int(a), int(b), str(t)) for a, b, t in d["rods"]),
                strings=tuple(String(int(a), int(b), str(t)) for a, b, t in d["strings"]),
                rod_materials=tuple(sorted((t, RodMaterial(**m)) for t, m in d["rod_materials"].items())),
                string_materials=tuple(sorted((t, StringMaterial(**m))
                                              for t, m in d["string_materials"].items())),
            )
        except (KeyError, TypeError, ValueError) as exc:
            if isinstance(exc, MorphologySpecError | ConfigError):
                raise
            raise MorphologySpecError("structure dict is malformed", received=repr(exc),
                                      expected="the keys written by StructureSpec.to_dict") from exc

    def spec_hash(self) -> str:
        blob = json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(blob.encode()).hexdigest()[:16]


def rotation_from_y(direction: np.ndarray) -> np.ndarray:
    """Shortest-arc rotation matrix taking +Y to unit(direction) (NTRT's rod orientation)."""
    d = np.asarray(direction, dtype=float) / fm.norm(direction)
    y = np.array([0.0, 1.0, 0.0])
    c = fm.dot(y, d)
    if c < -1.0 + 1e-12:  # antiparallel: any perpendicular axis works; use X for determinism
        return np.diag([1.0, -1.0, -1.0])
    v = np.cross(y, d)
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + fm.matmul(vx, vx) / (1.0 + c)


def rotation_matrix(axis: tuple[float, float, float], angle_rad: float) -> np.ndarray:
    """Right-handed rotation about `axis` by `angle_rad` (Rodrigues)."""
    a = np.asarray(axis, dtype=float)
    a = a / fm.norm(a)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle_rad) * k + (1 - math.cos(angle_rad)) * fm.matmul(k, k)
