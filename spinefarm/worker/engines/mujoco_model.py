"""The MuJoCo backend's model: its settings and the MJCF of a world (worker.engines.mujoco steps it).

Same world as the Bullet backend: cm, kg, s, Y up, gravity -981 cm/s^2 (MuJoCo is unit-free; its
only length tolerance that matters here, solimp's width, is given in cm). Each segment is one free
body whose frame is its COM with world-aligned axes at build time, with explicit mass and diagonal
inertia. String wrenches go straight into `xfrc_applied` (force at the COM and torque about it, world
frame: no force couple needed); poses are read from `qpos` after mj_step (xpos/xquat are those of the
step's start).

Contacts: rods are capsules. On plane terrains (flat ground, slope) a plane touches a capsule only at
an end cap, so `contact_geometry="ends"` (the default there) replaces each segment's rods by one
sphere per distinct rod end for terrain contact (a Tetraspine segment: 4 spheres instead of 6 rods
giving 6 nearly redundant contacts); segment-segment contacts stay capsule-capsule. Rough ground and
obstacles touch rods anywhere: capsules. "cylinders" gives every rod Bullet's shape instead (for
comparisons: on flat ground it stands where Bullet's spine stands).

Friction: MuJoCo takes the larger of two geoms' coefficients (or the one of higher priority); Bullet
multiplies them. Terrain geoms get priority and the coefficient mu_terrain * mu_rod, rod geoms mu_rod^2,
so terrain and segment-segment contacts see the same products as in Bullet (exact while every segment
has the same rod friction, as every built-in does). Sliding friction only (condim 3): Bullet's rolling
friction is the product with the ground's 0, its spinning friction 0. The friction cone is elliptic by
default: Coulomb's mu * N against sliding in any direction, as in Bullet; MuJoCo's pyramidal cone (four
edges) gives only mu / sqrt(2) between a contact's two axes.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from spinefarm.protocol.errors import ConfigError, bounded, check_fields, whole
from spinefarm.robot import fixedmath as fm
from spinefarm.robot.bodies import BodyModel, Quaternion, quaternion_matrix
from spinefarm.robot.scene import GROUND_TOP_CM, Box, Terrain
from spinefarm.worker.engines.base import GRAVITY_CM_S2

log = logging.getLogger("spinefarm.mujoco")
# MuJoCo's own warnings (e.g. "Nan, Inf or huge value in QACC" of a diverging trial) would go to stdout and
# a MUJOCO_LOG.TXT in the user's working directory; the divergence guard reports the trial, so they are
# debug detail here
mujoco.set_mju_user_warning(lambda message: log.debug("mujoco: %s", message))

INTEGRATORS = {"euler": mujoco.mjtIntegrator.mjINT_EULER, "implicit": mujoco.mjtIntegrator.mjINT_IMPLICIT,
               "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST, "rk4": mujoco.mjtIntegrator.mjINT_RK4}
CONES = {"pyramidal": mujoco.mjtCone.mjCONE_PYRAMIDAL, "elliptic": mujoco.mjtCone.mjCONE_ELLIPTIC}
SOLVERS = {"newton": mujoco.mjtSolver.mjSOL_NEWTON, "cg": mujoco.mjtSolver.mjSOL_CG,
           "pgs": mujoco.mjtSolver.mjSOL_PGS}
CONTACT_GEOMETRIES = ("auto", "ends", "capsules", "cylinders")
SEGMENT_CONTACTS = ("auto", "scene", "off", "reach")
# contype/conaffinity bits: terrain, terrain-only proxies, capsules (segment-segment, and terrain in
# "capsules" mode). Two geoms collide if (contype1 & conaffinity2) or (contype2 & conaffinity1).
_TERRAIN = (1, 0)
_END_PROXY = (0, 1)
_CAPSULE_SELF = (2, 2)
_CAPSULE_ALL = (2, 3)
PLANE_ASPECT = 100.0  # a box this much wider than thick is a plane (its top face) for contacts
EXPLICIT_FRACTION = 0.5  # "reach": a segment pair gets explicit rod pairs when at most this share can touch
POSE_COLUMNS = np.array([0, 1, 2, 4, 5, 6, 3], dtype=np.int64)  # qpos (x y z qw qx qy qz) -> (x y z qx qy qz qw)


@dataclass(frozen=True)
class MujocoSettings:
    """MuJoCo's numerical and contact settings (engine_options of a TrialConfig with engine "mujoco").

    solref_time_s, solref_damping_ratio: contact stiffness as a time constant and damping ratio
    (0.005 s converges best on the Tetraspine; MuJoCo clamps it to >= 2 dt). solimp: MuJoCo's
    impedance (d0, dwidth, width_cm, midpoint, power). contact_geometry: "auto" (rod-end spheres on
    plane terrains, capsules otherwise), "ends", "capsules" or "cylinders" (Bullet's rod shape).
    segment_contacts: "auto" (modelled only if a trial needs them: left out while a guard sees every gap
    stay open, see worker.engines.contact_guard; the same bits as "scene"), "scene" (segments collide as
    the scene's collision filter says), "off" (segments touch only the terrain) or "reach" (as "scene",
    less the rod pairs the structure can never bring within reach, robot.reach: see reach_plan).
    islands: MuJoCo's constraint island discovery (slower here: every segment is its own island).
    noslip_iterations: MuJoCo's no-slip pass after the solve (0: off), which removes the slow sliding of
    loaded contacts that soft friction allows.
    """

    integrator: str = "implicitfast"
    cone: str = "elliptic"
    solver: str = "newton"
    iterations: int = whole(100, 1, 10_000)
    ls_iterations: int = whole(50, 1, 10_000)
    tolerance: float = bounded(1e-8, 0.0, 1.0)
    solref_time_s: float = bounded(0.005, 0.0, 1.0, low_inclusive=False)
    solref_damping_ratio: float = bounded(1.0, 0.0, 100.0, low_inclusive=False)
    solimp: tuple[float, float, float, float, float] = (0.9, 0.95, 0.001, 0.5, 2.0)
    contact_geometry: str = "auto"
    segment_contacts: str = "auto"
    islands: bool = False
    noslip_iterations: int = whole(0, 0, 10_000)
    margin_cm: float = bounded(0.0, 0.0, 10.0)
    gravity_cm_s2: float = bounded(GRAVITY_CM_S2, 0.0)

    def __post_init__(self) -> None:
        for name, table in (("integrator", INTEGRATORS), ("cone", CONES), ("solver", SOLVERS)):
            if getattr(self, name) not in table:
                raise ConfigError(f"unknown mujoco {name}", received=getattr(self, name), expected=sorted(table))
        if self.contact_geometry not in CONTACT_GEOMETRIES:
            raise ConfigError("unknown mujoco contact_geometry", received=self.contact_geometry,
                              expected=list(CONTACT_GEOMETRIES))
        if self.segment_contacts not in SEGMENT_CONTACTS:
            raise ConfigError("unknown mujoco segment_contacts", received=self.segment_contacts,
                              expected=list(SEGMENT_CONTACTS))
        if not isinstance(self.islands, bool):
            raise ConfigError("islands is not a boolean", received=self.islands, expected="true or false")
        check_fields(self)
        try:
            solimp = tuple(float(v) for v in self.solimp)
        except (TypeError, ValueError) as exc:
            raise ConfigError("solimp is not five numbers", received=self.solimp,
                              expected="(d0, dwidth, width_cm, midpoint, power)") from exc
        if len(solimp) != 5 or not (0 < solimp[0] < 1 and 0 < solimp[1] < 1 and solimp[2] > 0):
            raise ConfigError("solimp out of range", received=self.solimp,
                              expected="(d0, dwidth, width_cm, midpoint, power) with 0 < d0, dwidth < 1, width > 0")
        object.__setattr__(self, "solimp", solimp)


def _f(v: float) -> str:
    return f"{float(v):.17g}"


def _vec(v: Sequence[float] | np.ndarray) -> str:
    return " ".join(_f(x) for x in v)


def _wxyz(q_xyzw: Sequence[float] | np.ndarray) -> tuple[float, float, float, float]:
    x, y, z, w = (float(v) for v in q_xyzw)
    return (w, x, y, z)


# MuJoCo planes and heightfields face +z of their frame; this turns +z into world +y (local y -> world -z)
_Z_UP_TO_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
_Z_UP_TO_Y_UP_WXYZ = (math.sqrt(0.5), -math.sqrt(0.5), 0.0, 0.0)


def _quat_wxyz_from_matrix(r: np.ndarray) -> tuple[float, float, float, float]:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(r, dtype=np.float64).ravel())
    return tuple(float(v) for v in q)


def rod_ends(body: BodyModel) -> list[tuple[np.ndarray, float]]:
    """Distinct rod end points of a segment in its frame (cm), each with the largest radius there."""
    ends: dict[tuple[float, ...], tuple[np.ndarray, float]] = {}
    for rod in body.rods:
        axis = rod.rotation[:, 1] * (rod.length_cm / 2)
        for p in (rod.centre_cm - axis, rod.centre_cm + axis):
            key = tuple(np.round(p, 6))
            if key not in ends or ends[key][1] < rod.radius_cm:
                ends[key] = (p, rod.radius_cm)
    return list(ends.values())


def _terrain_xml(terrain: Terrain, attributes: str) -> tuple[list[str], list[str]]:
    """(worldbody geoms, assets) of the terrain; `attributes`: friction, contact bits and solver settings."""
    world, assets = [], []
    for i, box in enumerate(terrain.boxes):
        rot = quaternion_matrix(box.quaternion)
        if _is_plane(box):
            top = np.asarray(box.centre_cm) + fm.matvec(rot, np.array([0.0, box.half_extents_cm[1], 0.0]))
            hx, _, hz = box.half_extents_cm
            quat = _quat_wxyz_from_matrix(fm.matmul(rot, _Z_UP_TO_Y_UP))
            world.append(f'<geom name="terrain{i}" type="plane" pos="{_vec(top)}" '
                         f'quat="{_vec(quat)}" size="{_f(hx)} {_f(hz)} 1" '
                         f'{attributes}/>')
        else:
            world.append(f'<geom name="terrain{i}" type="box" pos="{_vec(box.centre_cm)}" '
                         f'quat="{_vec(_wxyz(box.quaternion))}" size="{_vec(box.half_extents_cm)}" {attributes}/>')
    if terrain.heightfield is not None:
        hf = terrain.heightfield
        rows, cols = hf.heights_cm.shape
        lo, hi = float(hf.heights_cm.min()), float(hf.heights_cm.max())
        rx, rz = (cols - 1) * hf.spacing_cm / 2, (rows - 1) * hf.spacing_cm / 2
        assets.append(f'<hfield name="rough" nrow="{rows}" ncol="{cols}" '
                      f'size="{_f(rx)} {_f(rz)} {_f(max(hi - lo, 1e-6))} 1"/>')
        world.append(f'<geom name="heightfield" type="hfield" hfield="rough" pos="0 {_f(GROUND_TOP_CM + lo)} 0" '
                     f'quat="{_vec(_Z_UP_TO_Y_UP_WXYZ)}" {attributes}/>')
    return world, assets


def model_xml(bodies: list[BodyModel], terrain: Terrain, dt_s: float, settings: MujocoSettings,
              start_offsets_cm: np.ndarray | None, start_rotation: Quaternion | None,
              excluded: list[tuple[int, int]], rod_pairs: np.ndarray | None = None) -> str:
    """The MJCF of the world; heightfield elevations are filled in after compiling. rod_pairs (p, 4) rows (body
    a, rod of a, body b, rod of b): the segment-segment pairs of segment_contacts "reach"."""
    s = settings
    frictions = {b.friction for b in bodies}
    if len(frictions) > 1:
        raise ConfigError("the mujoco backend needs one rod friction for the whole robot (MuJoCo cannot "
                          "multiply per-pair coefficients)", received=sorted(frictions), expected="one value")
    mu_rod = frictions.pop() if frictions else 1.0
    geometry = s.contact_geometry
    if geometry == "auto":
        geometry = "capsules" if terrain.heightfield is not None or any(
            not _is_plane(b) for b in terrain.boxes) else "ends"
    solref = f'solref="{_f(s.solref_time_s)} {_f(s.solref_damping_ratio)}" solimp="{_vec(s.solimp)}"'
    common = f'condim="3" {solref} margin="{_f(s.margin_cm)}"'
    mu_terrain = terrain.friction * mu_rod
    tgeom = f'friction="{_f(mu_terrain)} 0 0" priority="1" contype="{_TERRAIN[0]}" conaffinity="{_TERRAIN[1]}"'
    world, assets = _terrain_xml(terrain, f"{tgeom} {common}")
    rot = np.eye(3) if start_rotation is None else quaternion_matrix(start_rotation)
    quat = "1 0 0 0" if start_rotation is None else _vec(_wxyz(start_rotation))
    capsule_bits = _CAPSULE_SELF if geometry == "ends" else _CAPSULE_ALL
    if s.segment_contacts not in ("scene", "reach"):  # "auto": left out while the guard sees no segment come near
        capsule_bits = (0, 0) if geometry == "ends" else _END_PROXY  # capsules touch the terrain only
    rgeom = f'friction="{_f(mu_rod * mu_rod)} 0 0" {common}'
    rod_type = "cylinder" if geometry == "cylinders" else "capsule"
    for i, body in enumerate(bodies):
        pos = fm.matvec(rot, body.com_cm) + (0.0 if start_offsets_cm is None else start_offsets_cm[i])
        parts = [f'<body name="s{i}" pos="{_vec(pos)}" quat="{quat}"><freejoint/>',
                 f'<inertial pos="0 0 0" mass="{_f(body.mass_kg)}" diaginertia="{_vec(body.inertia_kg_cm2)}"/>']
        for j, rod in enumerate(body.rods):
            half = rod.rotation[:, 1] * (rod.length_cm / 2)
            name = f'name="s{i}r{j}" ' if s.segment_contacts == "reach" else ""
            parts.append(f'<geom {name}type="{rod_type}" '
                         f'fromto="{_vec(rod.centre_cm - half)} {_vec(rod.centre_cm + half)}" '
                         f'size="{_f(rod.radius_cm)}" contype="{capsule_bits[0]}" conaffinity="{capsule_bits[1]}" '
                         f'{rgeom}/>')
        if geometry == "ends":
            for p, r in rod_ends(body):
                parts.append(f'<geom type="sphere" pos="{_vec(p)}" size="{_f(r)}" contype="{_END_PROXY[0]}" '
                             f'conaffinity="{_END_PROXY[1]}" {rgeom}/>')
        parts.append("</body>")
        world.append("".join(parts))
    pairs, explicit = (excluded, "") if s.segment_contacts == "scene" else ([], "")
    if s.segment_contacts == "reach":
        pairs, rows = reach_plan(bodies, excluded, rod_pairs)
        explicit = _pairs_xml(rows, mu_rod * mu_rod, f'{solref} margin="{_f(s.margin_cm)}"')
    excludes = explicit + "".join(f'<exclude body1="s{a}" body2="s{b}"/>' for a, b in pairs)
    integrator = {"euler": "Euler", "implicit": "implicit", "implicitfast": "implicitfast", "rk4": "RK4"}
    solver = {"newton": "Newton", "cg": "CG", "pgs": "PGS"}
    return (f'<mujoco model="spinefarm"><compiler angle="radian" inertiafromgeom="false"/>'
            f'<option timestep="{_f(dt_s)}" gravity="0 {_f(-s.gravity_cm_s2)} 0" '
            f'integrator="{integrator[s.integrator]}" cone="{s.cone}" solver="{solver[s.solver]}" '
            f'iterations="{s.iterations}" ls_iterations="{s.ls_iterations}" tolerance="{_f(s.tolerance)}" '
            f'noslip_iterations="{s.noslip_iterations}">'
            # a NaN must reach the divergence guard, not silently reset the world to its start
            f'<flag autoreset="disable" island="{"enable" if s.islands else "disable"}"/></option>'
            f'<asset>{"".join(assets)}</asset><worldbody>{"".join(world)}</worldbody>'
            f'<contact>{excludes}</contact></mujoco>')


def reach_plan(bodies: list[BodyModel], excluded: list[tuple[int, int]], rod_pairs: np.ndarray | None
               ) -> tuple[list[tuple[int, int]], np.ndarray]:
    """segment_contacts "reach": (segment pairs MuJoCo's own search leaves out, explicit rod pairs (p, 4)).
    rod_pairs (p, 4) rows (body a, rod of a, body b, rod of b), a < b: the pairs that can come within reach
    (None: all). A segment pair the scene filters out, or with no rod pair within reach, is left out; one
    with at most EXPLICIT_FRACTION of its rod pairs within reach is left out of the search and gets those
    pairs explicitly; any other stays in the search whole (a superset of its pairs within reach: MuJoCo's
    broadphase costs less per pair than explicit pairs, measured on the ribbed spine)."""
    kept: dict[tuple[int, int], list[int]] = {}
    rows = np.zeros((0, 4), dtype=np.int64) if rod_pairs is None else np.asarray(rod_pairs, dtype=np.int64)
    for n, (a, b) in enumerate(zip(rows[:, 0].tolist(), rows[:, 2].tolist(), strict=True)):
        kept.setdefault((a, b), []).append(n)
    blocked = {(min(a, b), max(a, b)) for a, b in excluded}
    out, explicit = [], []
    for a in range(len(bodies)):
        for b in range(a + 1, len(bodies)):
            total = len(bodies[a].rods) * len(bodies[b].rods)
            within = total if rod_pairs is None else len(kept.get((a, b), []))
            if (a, b) in blocked or within == 0:
                out.append((a, b))
            elif within <= EXPLICIT_FRACTION * total:
                out.append((a, b))
                explicit.extend(kept[a, b])
    return out, rows[np.array(explicit, dtype=np.int64)] if explicit else rows[:0]


def _pairs_xml(rod_pairs: np.ndarray | None, mu: float, solver: str) -> str:
    """Explicit contact pairs of rod capsules, with what MuJoCo would mix from the two rod geoms (condim 3,
    sliding friction mu both ways, the same solref, solimp and margin), so a pair's contact is the one
    "scene" makes."""
    friction = f'friction="{_f(mu)} {_f(mu)} 0 0 0"'
    return "".join(f'<pair geom1="s{a}r{i}" geom2="s{b}r{j}" condim="3" {friction} {solver}/>'
                   for a, i, b, j in (() if rod_pairs is None else rod_pairs.tolist()))


def _is_plane(box: Box) -> bool:
    hx, hy, hz = box.half_extents_cm
    return min(hx, hz) >= PLANE_ASPECT * hy


def fill_heightfield(model: mujoco.MjModel, terrain: Terrain) -> None:
    if terrain.heightfield is None:
        return
    h = terrain.heightfield.heights_cm
    span = max(float(h.max() - h.min()), 1e-6)
    # mjModel rows run along local +y = world -z, our rows along world +z
    model.hfield_data[:] = (np.flipud(h) - h.min()).ravel() / span


