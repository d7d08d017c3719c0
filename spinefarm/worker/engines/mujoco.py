"""The MuJoCo backend (with worker.engines.mujoco_model, the only modules that import mujoco): B worlds of
rigid segments on a terrain, soft contacts; the model, its settings and the contact scheme are described in
worker.engines.mujoco_model."""

from __future__ import annotations

import ctypes
from pathlib import Path

import mujoco
import numpy as np

from spinefarm.protocol.errors import ConfigError
from spinefarm.robot import fixedmath as fm
from spinefarm.robot.bodies import BodyModel, quaternion_matrix
from spinefarm.robot.scene import GroundSpec, Terrain, pairs_off
from spinefarm.worker.engines.base import BasePhysics, Vector3, world_offsets
from spinefarm.worker.engines.mujoco_model import (
    POSE_COLUMNS,
    MujocoSettings,
    fill_heightfield,
    model_xml,
)

__all__ = ["MujocoPhysics", "MujocoSettings", "mj_step_cfunc"]


def _libmujoco() -> ctypes.CDLL:
    lib = next(Path(mujoco.__file__).parent.glob("libmujoco.so*"), None)
    if lib is None:
        raise ConfigError("libmujoco not found next to the mujoco package", received=mujoco.__file__,
                          expected="a mujoco wheel with libmujoco.so")
    return ctypes.CDLL(str(lib))


_MJ_STEP = None
_STATE = mujoco.mjtState.mjSTATE_INTEGRATION  # what a snapshot keeps of a world


def mj_step_cfunc() -> ctypes._CFuncPtr:
    """mj_step as a ctypes function of two addresses (model, data), callable from compiled code."""
    global _MJ_STEP
    if _MJ_STEP is None:
        fn = _libmujoco().mj_step
        fn.argtypes = [ctypes.c_uint64, ctypes.c_uint64]
        fn.restype = None
        _MJ_STEP = fn
    return _MJ_STEP


class MujocoPhysics(BasePhysics):
    """One MuJoCo model holding the segments and the terrain, and B data (worlds) stepped one after another.

    The model is built with world 0's start offsets; every other world is placed by reset's arithmetic, the
    same bits as a model built with its own offsets."""

    name = "mujoco"
    settings_type = MujocoSettings

    def __init__(self, bodies: list[BodyModel], ground: GroundSpec | Terrain, dt_s: float = 1e-3,
                 settings: MujocoSettings | None = None, start_offsets_cm: np.ndarray | None = None,
                 start_rotation: tuple[float, float, float, float] | None = None,
                 collision_pairs_off: list[tuple[int, int]] | None = None, n_worlds: int | None = None,
                 rod_pairs: np.ndarray | None = None) -> None:
        self.settings = settings or MujocoSettings()
        offsets = world_offsets(start_offsets_cm, n_worlds, len(bodies))
        terrain = ground.to_terrain() if isinstance(ground, GroundSpec) else ground
        off = collision_pairs_off if collision_pairs_off is not None else pairs_off(terrain, len(bodies))
        self.xml = model_xml(bodies, terrain, dt_s, self.settings, offsets[0], start_rotation, off, rod_pairs)
        self.model = mujoco.MjModel.from_xml_string(self.xml)
        fill_heightfield(self.model, terrain)
        self.dt_s, self.n_bodies, self.n_worlds = dt_s, len(bodies), len(offsets)
        rot = np.eye(3) if start_rotation is None else quaternion_matrix(start_rotation)
        self.base_pos = np.array([fm.matvec(rot, b.com_cm) for b in bodies])  # start COMs before offsets
        self.guard = None
        if self.settings.segment_contacts == "auto":
            from spinefarm.worker.engines.contact_guard import SegmentContactGuard  # compiled: numba only when used

            self.guard = SegmentContactGuard(bodies, off)
        self.data = [mujoco.MjData(self.model) for _ in offsets]
        self._bind()
        for b in range(1, self.n_worlds):
            self._place(b, offsets[b])
        self._start_trial()

    @staticmethod
    def wants_rod_pairs(settings: MujocoSettings) -> bool:
        return settings.segment_contacts == "reach"

    def _bind(self) -> None:
        nb = self.n_bodies
        self.qpos = [d.qpos.reshape(nb, 7) for d in self.data]  # views: x y z, qw qx qy qz per body
        self.qvel = [d.qvel.reshape(nb, 6) for d in self.data]
        self.xfrc = [d.xfrc_applied[1:] for d in self.data]  # (nb, 6) force, torque; body 0 is the world
        self._poses = np.zeros((self.n_worlds, nb, 7))
        self._order = POSE_COLUMNS

    def _start_trial(self) -> None:
        self.retries = {}
        self._steps = np.zeros(self.n_worlds, dtype=np.int64)  # since the start, for the contact guard
        self._safe_until = np.zeros(self.n_worlds, dtype=np.int64)

    def _place(self, b: int, offsets: np.ndarray | None) -> None:
        mujoco.mj_resetData(self.model, self.data[b])
        # the same arithmetic as the model's build, so a reset world and a fresh one hold the same bits
        self.qpos[b][:, :3] = self.base_pos + (0.0 if offsets is None else offsets)

    def reset(self, start_offsets_cm: np.ndarray | None = None) -> None:
        """Every world back to the build pose (optionally shifted per world and body by start_offsets_cm
        (B, nb, 3), or (nb, 3) for one world) at rest: the state of freshly built worlds, without recompiling."""
        for b, offsets in enumerate(world_offsets(start_offsets_cm, self.n_worlds, self.n_bodies)):
            self._place(b, offsets)
        self._start_trial()

    def read_poses(self) -> np.ndarray:
        """(B, n_bodies, 7): COM position (cm) and quaternion (x, y, z, w) of each segment."""
        for b, qpos in enumerate(self.qpos):
            np.take(qpos, self._order, axis=1, out=self._poses[b])
        return self._poses

    def apply_wrenches(self, force: np.ndarray, torque: np.ndarray, active: np.ndarray | None = None) -> None:
        for b, xfrc in enumerate(self.xfrc):
            if active is None or active[b]:
                xfrc[:, :3] = force[b]
                xfrc[:, 3:] = torque[b]

    def step(self, active: np.ndarray | None = None) -> None:
        for b, data in enumerate(self.data):
            if active is None or active[b]:
                mujoco.mj_step(self.model, data)

    def snapshot(self, world: int) -> tuple:
        """(the world's integration state, its contact guard's step counts): all a world needs to go on. MuJoCo's
        mjSTATE_INTEGRATION (time, positions, velocities, warm start, applied forces: about 1 kB for the Tetraspine)
        rather than a copy of the MjData, which allocates its whole arena (18 MB here) for each kept world."""
        state = np.empty(mujoco.mj_stateSize(self.model, _STATE))
        mujoco.mj_getState(self.model, self.data[world], state, _STATE)
        return state, self._steps[world], self._safe_until[world]

    def restore(self, world: int, state: tuple) -> None:
        saved, steps, safe_until = state
        mujoco.mj_setState(self.model, self.data[world], saved, _STATE)  # in place: the bound views stay valid
        self._steps[world], self._safe_until[world] = steps, safe_until

    def compiled_worlds(self) -> list[tuple]:
        """Per world (address of mj_step, model address, data address, qpos (nb, 7), POSE_COLUMNS, xfrc (nb, 6));
        see worker.trial.loop."""
        step = ctypes.cast(mj_step_cfunc(), ctypes.c_void_p).value
        return [(step, self.model._address, d._address, q, self._order, x) for d, q, x in
                zip(self.data, self.qpos, self.xfrc, strict=True)]

    def steps_ahead(self, active: np.ndarray, n_steps: int, horizon_steps: int) -> int:
        """With segment_contacts "auto", runs of steps no longer than the contact guard finds safe: it looks
        again (at most horizon_steps ahead) at a world that has reached the end of its safe steps, counted by the
        world's own clock; a world for which not even one step is safe leaves `active` for `retries` (run it
        again from its start with segment_contacts "scene")."""
        if self.guard is None:
            return n_steps
        timestep = self.model.opt.timestep
        steps, safe_until = self._steps, self._safe_until
        ahead = n_steps
        for b, data in enumerate(self.data):  # per world, not per body: a few attribute reads
            if not active[b]:
                continue
            steps[b] = round(data.time / timestep)
            if steps[b] == safe_until[b]:
                self._look(b, active, horizon_steps)
            if active[b]:
                ahead = min(ahead, int(safe_until[b] - steps[b]))
        return ahead if active.any() else 0

    def compiled_look(self, world: int) -> tuple | None:
        """The contact guard's look as worker.trial.loop.run_checked runs it between compiled steps: (qvel
        (nb, 6), the guard's kernel arguments, dt_s, step counts (B,), safe-until steps (B,)), the counts in
        step with the world's clock; None without a guard (segment contacts modelled or off)."""
        if self.guard is None:
            return None
        self._steps[world] = round(self.data[world].time / self.model.opt.timestep)
        return (self.qvel[world], *self.guard.kernel_args, self.dt_s, self._steps, self._safe_until)

    def _look(self, b: int, active: np.ndarray, horizon_steps: int) -> None:
        steps, why = self.contact_free_steps(horizon_steps, b)
        if steps == 0:
            why = f"{why}, t={self._steps[b] * self.dt_s:.3f} s"
            self.retries[b] = ({"segment_contacts": "scene"}, {"segment_contacts": f"modelled: {why}"})
            active[b] = False
        self._safe_until[b] = self._steps[b] + steps

    def contact_free_steps(self, max_steps: int, world: int = 0) -> tuple[int, str]:
        """(steps, at most max_steps, before which none of the segment-segment contacts this model leaves
        out ("auto") can form in `world`; why not even one step is safe, or ""). Always max_steps when they
        are modelled or switched off."""
        if self.guard is None:
            return max_steps, ""
        t_free, gap = self.guard.free_time_s(self.qpos[world], self.qvel[world], max_steps * self.dt_s)
        steps = min(max_steps, int(t_free / self.dt_s * (1.0 + 1e-12)))
        # short: it travels in the result's extras (protocol.results.MAX_EXTRA_TEXT_CHARS)
        return steps, "" if steps else f"gap {gap:.3g} cm < one {self.dt_s * 1e3:g} ms step"

    def velocities(self) -> np.ndarray:
        """(B, n_bodies, 6): linear (cm/s) and angular (rad/s) velocity in the world frame; for checks."""
        out = np.zeros((self.n_worlds, self.n_bodies, 6))
        poses = self.read_poses()
        for w in range(self.n_worlds):
            for b in range(self.n_bodies):
                out[w, b, :3] = self.qvel[w][b, :3]
                # a free joint's angular velocity is in the body frame
                out[w, b, 3:] = fm.matvec(quaternion_matrix(poses[w, b, 3:]), self.qvel[w][b, 3:])
        return out

    def set_velocity(self, index: int, linear_cm_s: Vector3, angular_rad_s: Vector3 = (0.0, 0.0, 0.0),
                     world: int = 0) -> None:
        """Set one body's world-frame velocity; for checks and tests."""
        rot = quaternion_matrix(self.read_poses()[world, index, 3:])
        self.qvel[world][index, :3] = linear_cm_s
        self.qvel[world][index, 3:] = fm.matvec(rot.T, angular_rad_s)

    def set_state(self, world: int, poses: np.ndarray, velocities: np.ndarray) -> None:
        """Every body at poses (nb, 7) with velocities (nb, 6), world frame; the contact guard looks afresh."""
        self.qpos[world][:, :3] = poses[:, :3]
        self.qpos[world][:, 3] = poses[:, 6]  # MuJoCo's quaternion is (w, x, y, z)
        self.qpos[world][:, 4:] = poses[:, 3:6]
        self.qvel[world][:, :3] = velocities[:, :3]
        for b in range(self.n_bodies):  # a free joint's angular velocity is in the body frame
            self.qvel[world][b, 3:] = fm.matvec(quaternion_matrix(poses[b, 3:]).T, velocities[b, 3:])
        self._steps[world] = self._safe_until[world] = 0

    def contact_count(self, world: int = 0) -> int:
        return int(self.data[world].ncon)

    def close(self) -> None:
        self.data = []
        self.model = None
