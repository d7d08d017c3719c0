"""The trial loop, engine-neutral: per physics step and world, read the poses, run the control law
(worker.control.law), write the net wrench of every body, step.

`advance(engine, law, n_steps, active, horizon_steps, on_step)` runs n_steps of every active world. The
engine decides how (BasePhysics.advance: it may split the steps, e.g. to look for contacts it left out, or
drop a world it must run again in other settings). Each run of steps goes one of two ways, the same law and
the same bits either way:
  - step by step through the seam: engine.read_poses() -> law.step() -> engine.apply_wrenches() ->
    engine.step(); used when recording (on_step sees every step) and for engines without a compiled step;
  - compiled (engines declaring "compiled_step"): per world, one compiled call runs the steps, reading the
    engine's state array, calling the law and writing its wrench array, and calling the engine's C step
    function between them. The engine hands over data and a C function, nothing of the law.
A world whose law step fails (non-finite string state) drops out of `active`; law.steps says how many steps
of the phase it took.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numba import njit
from spinefarm.robot.engines import engine_spec
from spinefarm.worker.control.law import STATUS_OK, ControlLaw, law_step_world
from spinefarm.worker.engines.base import BasePhysics

OnStep = Callable[[np.ndarray, np.ndarray], None]


@njit(cache=True)
def run_compiled(step_fn, world, cpg, strings, clock, b, n_steps, poses):
    """n_steps of world b in one call. world = (model address, data address, state (nb, k), pose_columns (7,),
    wrench (nb, 6)): poses[i, c] = state[i, pose_columns[c]]; wrench rows take force then torque; step_fn(model,
    data) advances the world. Returns (status, steps taken)."""
    m_addr, d_addr, state, columns, wrench = world
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
        step_fn(m_addr, d_addr)
    return STATUS_OK, n_steps


def _steps(engine: BasePhysics, law: ControlLaw, on_step: OnStep | None) -> Callable[[int, np.ndarray], None]:
    """run(k, active): k steps of the active worlds; a world whose law fails leaves `active`."""
    if on_step is None and engine_spec(engine.name).can("compiled_step"):
        worlds, step_fn = engine.compiled_worlds()
        poses = np.zeros((engine.n_bodies, 7))

        def run(k: int, active: np.ndarray) -> None:
            for b in np.flatnonzero(active):
                status, _ = run_compiled(step_fn, worlds[b], law.cpg, law.strings, law.clock, b, k, poses)
                if status != STATUS_OK:
                    active[b] = False
        return run
    read, apply, step = engine.read_poses, engine.apply_wrenches, engine.step

    def run_python(k: int, active: np.ndarray) -> None:
        for _ in range(k):
            poses = read()
            status = law.step(poses, active)
            if np.any(status[active] != STATUS_OK):
                active &= status == STATUS_OK
                if not active.any():
                    return
            if on_step is not None:
                on_step(poses, active)
            apply(law.force, law.torque, active)
            step(active)
    return run_python


def advance(engine: BasePhysics, law: ControlLaw, n_steps: int, active: np.ndarray, horizon_steps: int,
            on_step: OnStep | None = None) -> None:
    """n_steps of every active world (active (B,) bool, updated in place). horizon_steps: the caller looks
    at the state that often (an engine may plan that far ahead). on_step(poses (B, nb, 7), active) is called
    every step after the law, before the wrench is applied (for recording)."""
    engine.advance(_steps(engine, law, on_step), n_steps, active, horizon_steps)
