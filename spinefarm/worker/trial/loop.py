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
of the phase it took. `checked_runner(engine, law)` runs a one-world trial's whole check intervals in one
compiled call (run_checked: the engine's look policy taken as data, compiled_look; run_compiled's steps; the
guard's fast check), the same bits as `advance` and worker.trial.batch's checks; Batch falls back to those
where it stops early.
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
from spinefarm.worker.engines.contact_guard import SegmentContactGuard, contact_free_time
from spinefarm.worker.trial.guard import check_clear

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


# how run_checked stopped: every step run; a law step failed; the engine's look found no safe step (its own
# steps_ahead then looks again and words why); a check the fast path could not call sane (the exact one decides)
RAN_ALL, RAN_LAW_FAILED, RAN_LOOK_FAILED, RAN_CHECK_UNCLEAR = 0, 1, 2, 3


@njit(cache=True)
def _look_ok(state, look, b, horizon_steps):
    """MujocoPhysics.steps_ahead's look in compiled form (the same arithmetic): when world b has reached the end of
    its safe steps, how many more are safe (at most horizon_steps); False when not one is."""
    enabled, qvel, capsules, pairs, scratch, dt_s, steps, safe_until = look
    if not enabled or steps[b] != safe_until[b]:
        return True
    t_free, _ = contact_free_time(state, qvel, horizon_steps * dt_s, capsules, pairs, scratch)
    free = min(horizon_steps, int(t_free / dt_s * (1.0 + 1e-12)))
    if free == 0:
        return False
    safe_until[b] = steps[b] + free
    return True


@njit(cache=True)
def run_checked(world, cpg, strings, clock, b, n_steps, poses, look, check, com_rows):
    """n_steps of world b from a check, in whole check intervals, as worker.trial.batch.Batch runs them through
    `advance` and its checks, in one call: the engine's look when due (before the first piece and after each),
    the steps (run_compiled), and at every check the guard's fast path (guard.check_clear: COM into com_rows,
    the last sane pose). look = (enabled, qvel, contact guard arguments, dt_s, steps (B,), safe_until (B,));
    check = (check_every, last, last_good, masses, mass_total, lprev column, base lengths, interval_s, boxes,
    limits, pose buffer (nb, 7), work at the last sane check (1,)). Returns (RAN_*, steps taken, sane checks)."""
    state, columns = world[3], world[4]
    every, last, last_good, masses, mass_total, lprev, base_len, interval_s, boxes, limits, seen, work_at = check
    enabled, steps = look[0], look[6]
    sstate, work = strings[5][b], strings[9]
    if not _look_ok(state, look, b, every):
        return RAN_LOOK_FAILED, 0, 0
    done = 0
    checks = 0
    while done < n_steps:
        k = every - done % every
        if enabled:
            k = min(k, look[7][b] - steps[b])
        status, ran = run_compiled(world, cpg, strings, clock, b, k, poses)
        done += ran
        steps[b] += ran
        if status != STATUS_OK:
            return RAN_LAW_FAILED, done, checks
        if not _look_ok(state, look, b, every):
            return RAN_LOOK_FAILED, done, checks
        if done % every == 0:
            for i in range(seen.shape[0]):
                for c in range(7):
                    seen[i, c] = state[i, columns[c]]
            if not check_clear(seen, last, last_good, masses, mass_total, sstate, lprev, base_len, interval_s, boxes,
                               limits, com_rows[checks]):
                return RAN_CHECK_UNCLEAR, done, checks
            work_at[0] = work[b, 0]
            checks += 1
    return RAN_ALL, done, checks


def checked_runner(engine: BasePhysics, law: ControlLaw) -> Callable[..., tuple[int, int, int]] | None:
    """run(b, n_steps, check, com_rows) -> run_checked's answer for world b, or None where the engine has no
    compiled step or no compiled form of its steps_ahead policy (Batch then runs `stepper`'s pieces)."""
    if not engine_spec(engine.name).can("compiled_step"):
        return None
    worlds = engine.compiled_worlds()
    try:
        engine.compiled_look(0)
    except NotImplementedError:
        return None
    poses = np.zeros((engine.n_bodies, 7))
    idle = np.zeros(len(worlds), dtype=np.int64)
    no_look = (False, np.zeros((engine.n_bodies, 6)), *SegmentContactGuard([], []).kernel_args, 1.0, idle, idle)

    def run(b: int, n_steps: int, check: tuple, com_rows: np.ndarray) -> tuple[int, int, int]:
        look = engine.compiled_look(b)  # its step count in step with the world's clock
        look = no_look if look is None else (True, *look)
        return run_checked(worlds[b], law.cpg, law.strings, law.clock, b, n_steps, poses, look, check, com_rows)
    return run


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
