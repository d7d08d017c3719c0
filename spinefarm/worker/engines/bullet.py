"""The Bullet backend (the only module that imports pybullet): compound rigid segments on a terrain.

Gravity is -981 cm/s^2 along Y (Y up, NTRT's frame). Each segment is one maximal-coordinate
rigid body with explicit mass, COM and inertia. Per step the loop does one pose read per body,
two applyExternalForce calls per body (its net wrench as a force pair, since pybullet's
applyExternalTorque is wrong on maximal-coordinate bodies) and one stepSimulation.
Friction: Bullet multiplies the two bodies' coefficients, so the spec's ground and rod values
apply as they are.
"""

from __future__ import annotations

import ctypes
import math
import os
import sys
import tempfile
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from itertools import chain

import numpy as np
import pybullet as pb

from spinefarm.protocol.errors import ConfigError, bounded, check_fields, whole
from spinefarm.robot import fixedmath as fm
from spinefarm.robot.bodies import BodyModel
from spinefarm.robot.scene import GROUND_TOP_CM, GroundSpec, Terrain, pairs_off
from spinefarm.worker.engines.base import GRAVITY_CM_S2, BasePhysics, Vector3, world_offsets
from spinefarm.worker.engines.couple import wrench_to_force_pairs

CONSTRAINT_SOLVERS = {"sequential_impulse": pb.CONSTRAINT_SOLVER_LCP_SI,
                      "mlcp_dantzig": pb.CONSTRAINT_SOLVER_LCP_DANTZIG}


@dataclass(frozen=True)
class BulletSettings:
    """Bullet settings; defaults are Bullet 2.8x's sequential-impulse defaults."""

    solver_iterations: int = whole(10, 1, 1000)
    erp: float = bounded(0.2, 0.0, 1.0)
    split_impulse: bool = True
    split_impulse_threshold: float = -0.04
    warm_starting_factor: float = bounded(0.85, 0.0, 1.0)
    cone_friction: bool = False
    gravity_cm_s2: float = bounded(GRAVITY_CM_S2, 0.0)
    # Bullet's friction anchors hold static contacts in place; without them a resting spine
    # creeps ~0.5 cm/s at dt = 1 ms (a drift proportional to dt). NTRT's Bullet 2.81 had none.
    friction_anchor: bool = True
    # "mlcp_dantzig": Bullet's MLCP solver with the Dantzig LCP solver, the one NTRT's current code (and its
    # recordings) use; the default keeps pybullet's sequential impulse, which NTRT's 2014 code used
    constraint_solver: str = "sequential_impulse"

    def __post_init__(self) -> None:
        check_fields(self)
        if self.constraint_solver not in CONSTRAINT_SOLVERS:
            raise ConfigError("unknown Bullet constraint_solver", received=self.constraint_solver,
                              expected=sorted(CONSTRAINT_SOLVERS))


def _quat_from_matrix(r: np.ndarray) -> tuple[float, float, float, float]:
    tr = r[0, 0] + r[1, 1] + r[2, 2]
    if tr > 0:
        s = np.sqrt(tr + 1.0) * 2
        w, x, y, z = 0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = np.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2]) * 2
        w, x, y, z = (r[2, 1] - r[1, 2]) / s, 0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s
    elif r[1, 1] > r[2, 2]:
        s = np.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2]) * 2
        w, x, y, z = (r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s
    else:
        s = np.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1]) * 2
        w, x, y, z = (r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s
    return (float(x), float(y), float(z), float(w))


_FD1_LOCK = threading.Lock()


@contextmanager
def _stdout_to_stderr() -> Iterator[None]:
    """File descriptor 1 sent to stderr for a while: pybullet's C code prints there (the MLCP solver's "Constraint
    Solver: MLCP + Dantzig" when it is chosen), which would break `spinefarm trial --json`. Process-wide: only
    for the calls that set a world up, one thread at a time (two overlapping would leave stdout on stderr)."""
    with _FD1_LOCK:
        sys.stdout.flush()
        saved = os.dup(1)
        try:
            os.dup2(2, 1)
            yield
        finally:
            ctypes.CDLL(None).fflush(None)  # C's buffered text goes out now, to stderr, not to stdout later
            os.dup2(saved, 1)
            os.close(saved)


def _connect(engine: BulletSettings, dt_s: float) -> int:
    """A DIRECT client set up by the engine's settings, pybullet's banners sent to stderr."""
    with _stdout_to_stderr():
        c = pb.connect(pb.DIRECT)
        pb.resetSimulation(physicsClientId=c)
        pb.setGravity(0.0, -engine.gravity_cm_s2, 0.0, physicsClientId=c)
        pb.setPhysicsEngineParameter(
            fixedTimeStep=dt_s, numSubSteps=1, numSolverIterations=engine.solver_iterations,
            erp=engine.erp, contactERP=engine.erp, frictionERP=engine.erp,
            useSplitImpulse=int(engine.split_impulse),
            splitImpulsePenetrationThreshold=engine.split_impulse_threshold,
            enableConeFriction=int(engine.cone_friction), deterministicOverlappingPairs=1,
            restitutionVelocityThreshold=0.0, physicsClientId=c)
        pb.setPhysicsEngineParameter(warmStartingFactor=engine.warm_starting_factor, physicsClientId=c)
        if engine.constraint_solver != "sequential_impulse":  # set only when asked: the default's bits unchanged
            pb.setPhysicsEngineParameter(constraintSolverType=CONSTRAINT_SOLVERS[engine.constraint_solver],
                                         physicsClientId=c)
    return c


# pybullet cylinders run along Z; our rods along their frame's Y.
_Z_TO_Y = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
# createCollisionShapeArray silently keeps only the first 16 shapes (MAX_COMPOUND_COLLISION_SHAPES);
# larger segments (the ribbed spine's 33 rods) are loaded as a one-link URDF, whose compound has no cap.
MAX_SHAPE_ARRAY = 16


def _rpy(r: np.ndarray) -> tuple[float, float, float]:
    """URDF roll, pitch, yaw of a rotation matrix r = Rz(yaw) Ry(pitch) Rx(roll). glibc's asin and atan2
    (math), not numpy's: numpy runs its own vectorised ones on AVX-512 CPUs, and the bits would differ."""
    r = [[float(v) for v in row] for row in r]
    pitch = math.asin(min(1.0, max(-1.0, -r[2][0])))
    if abs(r[2][0]) < 1.0 - 1e-12:
        return math.atan2(r[2][1], r[2][2]), pitch, math.atan2(r[1][0], r[0][0])
    return math.atan2(-r[1][2], r[1][1]), pitch, 0.0  # gimbal lock: put it all in roll


def _load_compound_urdf(body: BodyModel, pos: np.ndarray, quat: tuple[float, ...], client: int) -> int:
    parts = []
    for rod in body.rods:
        x, y, z = (f"{v:.17g}" for v in rod.centre_cm)
        roll, pitch, yaw = (f"{v:.17g}" for v in _rpy(fm.matmul(rod.rotation, _Z_TO_Y)))
        parts.append(f'<collision><origin xyz="{x} {y} {z}" rpy="{roll} {pitch} {yaw}"/><geometry>'
                     f'<cylinder radius="{rod.radius_cm:.17g}" length="{rod.length_cm:.17g}"/></geometry></collision>')
    ixx, iyy, izz = (f"{v:.17g}" for v in body.inertia_kg_cm2)
    urdf = (f'<robot name="segment{body.index}"><link name="base"><inertial><origin xyz="0 0 0"/>'
            f'<mass value="{body.mass_kg:.17g}"/><inertia ixx="{ixx}" iyy="{iyy}" izz="{izz}" ixy="0" ixz="0" '
            f'iyz="0"/></inertial>{"".join(parts)}</link></robot>')
    fd, path = tempfile.mkstemp(suffix=".urdf")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(urdf)
        return pb.loadURDF(path, list(map(float, pos)), list(quat), useMaximalCoordinates=True,
                           flags=pb.URDF_USE_IMPLICIT_CYLINDER | pb.URDF_USE_INERTIA_FROM_FILE,
                           physicsClientId=client)
    finally:
        os.unlink(path)


class BulletPhysics(BasePhysics):
    """B pybullet DIRECT worlds (one client each), stepped one after another."""

    name = "bullet"
    settings_type = BulletSettings

    def __init__(self, bodies: list[BodyModel], ground: GroundSpec | Terrain, dt_s: float = 1e-3,
                 settings: BulletSettings | None = None, start_offsets_cm: np.ndarray | None = None,
                 start_rotation: tuple[float, float, float, float] | None = None,
                 collision_pairs_off: list[tuple[int, int]] | None = None, n_worlds: int | None = None) -> None:
        offsets = world_offsets(start_offsets_cm, n_worlds, len(bodies))
        self.worlds = [BulletWorld(bodies, ground, dt_s, settings, o, start_rotation, collision_pairs_off)
                       for o in offsets]
        self.n_worlds, self.n_bodies, self.dt_s = len(self.worlds), len(bodies), dt_s
        self.retries = {}
        self._poses = np.zeros((self.n_worlds, self.n_bodies, 7))

    def read_poses(self) -> np.ndarray:
        """(B, n_bodies, 7): COM position (cm) and quaternion (x, y, z, w) of each segment."""
        for b, world in enumerate(self.worlds):
            self._poses[b] = world.read_poses()
        return self._poses

    def apply_wrenches(self, force: np.ndarray, torque: np.ndarray, active: np.ndarray | None = None) -> None:
        for b, world in enumerate(self.worlds):
            if active is None or active[b]:
                world.apply_wrenches(force[b], torque[b])

    def step(self, active: np.ndarray | None = None) -> None:
        for b, world in enumerate(self.worlds):
            if active is None or active[b]:
                world.step()

    def velocities(self) -> np.ndarray:
        """(B, n_bodies, 6): linear (cm/s) and angular (rad/s) velocity; for checks, not the hot loop."""
        return np.array([w.velocities() for w in self.worlds])

    def set_velocity(self, index: int, linear_cm_s: Vector3, angular_rad_s: Vector3 = (0.0, 0.0, 0.0),
                     world: int = 0) -> None:
        """Set one body's world-frame velocity; for checks and tests."""
        self.worlds[world].set_velocity(index, linear_cm_s, angular_rad_s)

    def set_state(self, world: int, poses: np.ndarray, velocities: np.ndarray) -> None:
        self.worlds[world].set_state(poses, velocities)

    def body_dynamics(self, index: int, world: int = 0) -> tuple:
        return self.worlds[world].body_dynamics(index)

    def close(self) -> None:
        for world in self.worlds:
            world.close()


class BulletWorld:
    """One pybullet DIRECT world holding the segments and the terrain."""

    def __init__(self, bodies: list[BodyModel], ground: GroundSpec | Terrain, dt_s: float,
                 settings: BulletSettings | None, start_offsets_cm: np.ndarray | None,
                 start_rotation: tuple[float, float, float, float] | None,
                 collision_pairs_off: list[tuple[int, int]] | None) -> None:
        engine = settings or BulletSettings()
        self.client = c = _connect(engine, dt_s)
        self.dt_s = dt_s
        self.friction_anchor = engine.friction_anchor
        terrain = ground.to_terrain() if isinstance(ground, GroundSpec) else ground
        self.terrain_ids = self._add_terrain(terrain)
        self.ground_id = self.terrain_ids[0]
        self.body_ids: list[int] = []
        for i, body in enumerate(bodies):
            self.body_ids.append(self._add_body(body, None if start_offsets_cm is None else start_offsets_cm[i],
                                                start_rotation))
        for a, b in collision_pairs_off if collision_pairs_off is not None else pairs_off(terrain, len(bodies)):
            pb.setCollisionFilterPair(self.body_ids[a], self.body_ids[b], -1, -1, 0, physicsClientId=c)
        self._get_pose = pb.getBasePositionAndOrientation
        self._apply = pb.applyExternalForce
        self._step = pb.stepSimulation
        self._world = pb.WORLD_FRAME
        self._points = np.zeros((2 * len(bodies), 3))
        self._forces = np.zeros((2 * len(bodies), 3))
        self._poses = np.zeros((len(bodies), 7))

    def _add_terrain(self, terrain: Terrain) -> list[int]:
        c = self.client
        ids = []
        for box in terrain.boxes:
            shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=list(box.half_extents_cm), physicsClientId=c)
            ids.append(pb.createMultiBody(0.0, shape, -1, list(box.centre_cm), list(box.quaternion),
                                          useMaximalCoordinates=True, physicsClientId=c))
        if terrain.heightfield is not None:
            hf = terrain.heightfield
            rows, cols = hf.heights_cm.shape
            shape = pb.createCollisionShape(
                pb.GEOM_HEIGHTFIELD, meshScale=[hf.spacing_cm, hf.spacing_cm, 1.0],
                heightfieldData=np.flipud(hf.heights_cm).ravel().tolist(), numHeightfieldRows=cols,
                numHeightfieldColumns=rows, physicsClientId=c)
            # Bullet centres a heightfield between its lowest and highest points, and its up axis is z:
            # rotate by -90 degrees about x so that local z is world y; local y is then world -z, hence the flip
            mid = 0.5 * (hf.heights_cm.min() + hf.heights_cm.max())
            s2 = math.sqrt(0.5)
            ids.append(pb.createMultiBody(0.0, shape, -1, [0.0, GROUND_TOP_CM + mid, 0.0], [-s2, 0.0, 0.0, s2],
                                          useMaximalCoordinates=True, physicsClientId=c))
        for tid in ids:
            pb.changeDynamics(tid, -1, lateralFriction=terrain.friction, restitution=0.0, rollingFriction=0.0,
                              spinningFriction=0.0, physicsClientId=c)
        return ids

    def _add_body(self, body: BodyModel, offset: np.ndarray | None,
                  rotation: tuple[float, float, float, float] | None = None) -> int:
        """A segment at its build pose, rotated about the world origin by `rotation` (x, y, z, w) and
        then shifted by `offset` (cm)."""
        c = self.client
        n = len(body.rods)
        quat = (0.0, 0.0, 0.0, 1.0) if rotation is None else tuple(map(float, rotation))
        pos = fm.matvec(np.array(pb.getMatrixFromQuaternion(quat)).reshape(3, 3), body.com_cm)
        pos = pos if offset is None else pos + offset
        if n > MAX_SHAPE_ARRAY:
            bid = _load_compound_urdf(body, pos, quat, c)
        else:
            shape = pb.createCollisionShapeArray(
                shapeTypes=[pb.GEOM_CYLINDER] * n,
                radii=[r.radius_cm for r in body.rods],
                lengths=[r.length_cm for r in body.rods],
                collisionFramePositions=[list(map(float, r.centre_cm)) for r in body.rods],
                collisionFrameOrientations=[_quat_from_matrix(fm.matmul(r.rotation, _Z_TO_Y)) for r in body.rods],
                physicsClientId=c)
            bid = pb.createMultiBody(body.mass_kg, shape, -1, list(map(float, pos)), list(quat),
                                     useMaximalCoordinates=True, physicsClientId=c)
        # mass in the same call as the inertia, or pybullet zeroes the mass
        pb.changeDynamics(bid, -1, mass=body.mass_kg, localInertiaDiagonal=list(map(float, body.inertia_kg_cm2)),
                          lateralFriction=body.friction, rollingFriction=body.rolling_friction,
                          spinningFriction=0.0, restitution=body.restitution, linearDamping=0.0,
                          angularDamping=0.0, activationState=pb.ACTIVATION_STATE_DISABLE_SLEEPING,
                          frictionAnchor=int(self.friction_anchor),
                          physicsClientId=c)
        return bid

    def read_poses(self) -> np.ndarray:
        """(n_bodies, 7): COM position (cm) and quaternion (x, y, z, w) of each segment."""
        get, c = self._get_pose, self.client
        # positional client id: the keyword form costs ~0.6 us more per call
        flat = chain.from_iterable(chain.from_iterable([get(b, c) for b in self.body_ids]))
        self._poses = np.fromiter(flat, float, 7 * len(self.body_ids)).reshape(-1, 7)
        return self._poses

    def apply_wrenches(self, force: np.ndarray, torque: np.ndarray) -> None:
        """Net force (n_bodies, 3) at each COM and torque (n_bodies, 3) about it, as two forces per body
        at the poses of the last read_poses()."""
        wrench_to_force_pairs(self._poses, force, torque, self._points, self._forces)
        self.apply_force_pairs(self._points, self._forces)

    def apply_force_pairs(self, points_cm: np.ndarray, forces: np.ndarray) -> None:
        """Apply forces (2 n_bodies, 3) kg*cm/s^2 at world points (2 n_bodies, 3); rows 2b, 2b+1 on body b."""
        apply, world, c = self._apply, self._world, self.client
        pts = points_cm.tolist()
        fs = forces.tolist()
        for i, b in enumerate(self.body_ids):
            apply(b, -1, fs[2 * i], pts[2 * i], world, c)
            apply(b, -1, fs[2 * i + 1], pts[2 * i + 1], world, c)

    def step(self) -> None:
        self._step(self.client)

    def velocities(self) -> np.ndarray:
        """(n_bodies, 6): linear (cm/s) and angular (rad/s) velocity; for checks, not the hot loop."""
        return np.array([tuple(chain.from_iterable(pb.getBaseVelocity(b, physicsClientId=self.client)))
                         for b in self.body_ids])

    def set_velocity(self, index: int, linear_cm_s: Vector3, angular_rad_s: Vector3 = (0.0, 0.0, 0.0)) -> None:
        """Set one body's world-frame velocity; for checks and tests."""
        pb.resetBaseVelocity(self.body_ids[index], list(map(float, linear_cm_s)), list(map(float, angular_rad_s)),
                             physicsClientId=self.client)

    def set_state(self, poses: np.ndarray, velocities: np.ndarray) -> None:
        """Every body at poses (nb, 7) with velocities (nb, 6), world frame (the base frame is the COM)."""
        for b, pose, vel in zip(self.body_ids, poses.tolist(), velocities.tolist(), strict=True):
            pb.resetBasePositionAndOrientation(b, pose[:3], pose[3:], physicsClientId=self.client)
            pb.resetBaseVelocity(b, vel[:3], vel[3:], physicsClientId=self.client)
        self._poses = np.asarray(poses, dtype=float).copy()

    def body_dynamics(self, index: int) -> tuple:
        return pb.getDynamicsInfo(self.body_ids[index], -1, physicsClientId=self.client)

    def close(self) -> None:
        if self.client is not None and pb.isConnected(self.client):
            pb.disconnect(self.client)
        self.client = None
