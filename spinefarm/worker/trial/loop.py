"""The trial loop, engine-neutral: per physics step and world, read the poses, run the control law
(worker.control.law), write the net wrench of every body, step.

`stepper(engine, law, on_step)` makes run(k, active), k steps of the active worlds; `advance(engine, run,
n_steps, active, horizon_steps)` runs n_steps of them in the pieces the engine's policy allows (asked, never
called back: BasePhysics.steps_ahead may shorten a piece, e.g. to look for contacts it left out, or drop a world
it must run again in other settings). Each run of steps goes one of two ways, the same law and
the same bits either way:
  - step by step through the seam: engine.read_poses() -> law.step() -> engine.apply_wrenches() ->
    engine.step(); used when recording (on_step sees every step) and for engines without a compiled step;
  - compiled (engines declaring "compiled_step"): per world, one compiled call runs the steps, reading the
    engine's state array, calling the law and writing its wrench array, and calling the engine's C step
    function (by its address) between them. The engine hands over data and a C function, nothing of the law.
A world whose law step fails (non-finite string state) drops out of `active`; law.steps says how many steps
of the phase it took.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

from spinefarm.robot.engines import engine_spec
from spinefarm.worker.control.law import STATUS_OK, ControlLaw, law_step_world
from spinefarm.worker.engines.base import BasePhysics

OnStep = Callable[[np.ndarray, np.ndarray], None]
Run = Callable[[int, np.ndarray], None]  # run(k, active): k steps of the active worlds


@intrinsic
def _call_step(typingctx, address, model, data):
    """Call the C function void step(uint64 model, uint64 data) at `address` (all three 64-bit integers)."""
    if not all(isinstance(t, types.Integer) for t in (address, model, data)):
        return None

    def codegen(context, builder, signature, args):
        i64 = ir.IntType(64)
        function = builder.inttoptr(args[0], ir.FunctionType(ir.VoidType(), [i64, i64]).as_pointer())
        builder.call(function, [args[1], args[2]])
        return context.get_dummy_value()
    return types.void(address, model, data), codegen


@njit(cache=True)
def run_compiled(world, cpg, strings, clock, b, n_steps, poses):
    """n_steps of world b in one call. world = (step function address, model address, data address, state
    (nb, k), pose_columns (7,), wrench (nb, 6)): poses[i, c] = state[i, pose_columns[c]]; wrench rows take
    force then torque; the C function step(model, data) advances the world. Returns (status, steps taken)."""
    step, m_addr, d_addr, state, columns, wrench = world
    force = strings[6][b]
    torque = strings[7][b]
    nb = poses.shape[0]
    for n in range(n_steps):
        for i in range(nb):
            for c in range(7):
                poses[i, c] = state[i, columns[c]]
        status = law_step_world(cpg, strings, clock, b, poses)
        if status != STATUS_OK:
            return status, n
        for i in range(nb):
            for c in range(3):
                wrench[i, c] = force[i, c]
                wrench[i, 3 + c] = torque[i, c]
        _call_step(step, m_addr, d_addr)
    return STATUS_OK, n_steps


def stepper(engine: BasePhysics, law: ControlLaw, on_step: OnStep | None = None) -> Run:
    """run(k, active): k steps of the active worlds (active (B,) bool, updated in place: a world whose law
    fails leaves it). on_step(poses (B, nb, 7), active) is called every step after the law, before the wrench
    is applied (for recording); without it an engine that declares "compiled_step" runs compiled."""
    if on_step is None and engine_spec(engine.name).can("compiled_step"):
        worlds = engine.compiled_worlds()
        poses = np.zeros((engine.n_bodies, 7))
        n_worlds = len(worlds)

        def run(k: int, active: np.ndarray) -> None:
            for b in range(n_worlds):
                if active[b]:
                    status, _ = run_compiled(worlds[b], law.cpg, law.strings, law.clock, b, k, poses)
                    if status != STATUS_OK:
                        active[b] = False
        return run
    read, apply, step = engine.read_poses, engine.apply_wrenches, engine.step

    def run_python(k: int, active: np.ndarray) -> None:
        for _ in range(k):
            poses = read()
            if law.step(poses, active):
                active &= law.status == STATUS_OK
                if not active.any():
                    return
            if on_step is not None:
                on_step(poses, active)
            apply(law.force, law.torque, active)
            step(active)
    return run_python


def advance(engine: BasePhysics, run: Run, n_steps: int, active: np.ndarray, horizon_steps: int) -> None:
    """n_steps of every active world through `run` (from stepper), in the pieces the engine's policy allows
    (BasePhysics.steps_ahead, asked before each piece and once after the last, so it may still hand a world
    back). horizon_steps: the caller looks at the state that often (an engine may plan that far ahead)."""
    done = 0
    k = engine.steps_ahead(active, n_steps, horizon_steps)
    while k > 0:
        run(k, active)
        done += k
        k = engine.steps_ahead(active, n_steps - done, horizon_steps)
