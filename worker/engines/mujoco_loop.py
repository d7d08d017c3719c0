"""The fused MuJoCo loop: read poses from qpos, advance the CPG when due, run the string kernel, write
the wrenches into xfrc_applied and call mj_step, for many steps in one compiled call.

The same kernels (worker.control.cpg.rk4_advance, worker.sim.strings.string_step) in the same order
as the generic per-step loop of worker.trial, so both give the same bits. mj_step is called through
its C symbol (libmujoco, loaded once per process), so no Python runs between two steps; the trial
loop returns to Python only for its divergence checks.
"""

from __future__ import annotations

from pathlib import Path

import llvmlite.binding as llvm
import mujoco
import numpy as np
from numba import njit, types
from spinefarm.worker.control.cpg import rk4_advance
from spinefarm.worker.sim.strings import STATUS_OK, string_step

_LIB = next(Path(mujoco.__file__).parent.glob("libmujoco.so*"), None)
if _LIB is not None:
    llvm.load_library_permanently(str(_LIB))  # resolves the mj_step symbol for compiled code
# mj_step(const mjModel*, mjData*): the addresses as 64-bit integers (same registers as pointers)
_mj_step = types.ExternalFunction("mj_step", types.void(types.uint64, types.uint64))


@njit(cache=True)
def run_steps(m_addr, d_addr, qpos, xfrc, poses, n0, n1, cpg_every, dt,
              cpg_state, omega, amp, indptr, source, wc, rate, h, n_sub, cpg_work, cpg_out,
              body_a, body_b, anc_a, anc_b, params, sstate, motor_mode, force, torque, tension, work,
              wa, wb, string_force):
    """Steps n0 .. n1-1 of the trial loop. Returns (status, step index reached): STATUS_OK and n1,
    or the string kernel's status and the index of the step that failed (not taken)."""
    nb = poses.shape[0]
    for n in range(n0, n1):
        for b in range(nb):
            poses[b, 0] = qpos[b, 0]
            poses[b, 1] = qpos[b, 1]
            poses[b, 2] = qpos[b, 2]
            poses[b, 3] = qpos[b, 4]
            poses[b, 4] = qpos[b, 5]
            poses[b, 5] = qpos[b, 6]
            poses[b, 6] = qpos[b, 3]
        if cpg_every > 0 and (n + 1) % cpg_every == 0:
            rk4_advance(cpg_state, omega, amp, indptr, source, wc, rate, h, n_sub, cpg_work, cpg_out)
        status = string_step(poses, body_a, body_b, anc_a, anc_b, params, sstate, cpg_out, dt, motor_mode,
                             force, torque, tension, work, wa, wb, string_force)
        if status != STATUS_OK:
            return status, n
        for b in range(nb):
            xfrc[b, 0] = force[b, 0]
            xfrc[b, 1] = force[b, 1]
            xfrc[b, 2] = force[b, 2]
            xfrc[b, 3] = torque[b, 0]
            xfrc[b, 4] = torque[b, 1]
            xfrc[b, 5] = torque[b, 2]
        _mj_step(m_addr, d_addr)
    return STATUS_OK, n1


class FusedStepper:
    """Runs chunks of the trial loop on a MujocoPhysics in one compiled call each.

    cpg_every: CPG update every that many steps (0: never, the CPG held, as in a settle phase).
    """

    def __init__(self, physics, bank, cpg, cpg_every: int, motor_mode: int) -> None:
        self.physics, self.bank, self.cpg = physics, bank, cpg
        self.kernel = cpg.kernel_arrays()
        self.cpg_every = cpg_every
        self.motor_mode = motor_mode
        self.dt = physics.dt_s
        self.h, self.n_sub = cpg.plan(cpg_every * self.dt) if cpg_every > 0 else (0.0, 0)
        self.poses = np.zeros((physics.n_bodies, 7))

    def run(self, n0: int, n1: int) -> tuple[int, int]:
        p, b, c = self.physics, self.bank, self.cpg
        return run_steps(p.model._address, p.data._address, p.qpos, p.xfrc, self.poses, n0, n1, self.cpg_every,
                         self.dt, c.state, *self.kernel, self.h, self.n_sub, c.work,
                         c.output_cm_s, b.body_a, b.body_b, b.anchor_a, b.anchor_b, b.params, b.state,
                         self.motor_mode, b.force, b.torque, b.tension, b.work, b.wa, b.wb, b.string_force)
