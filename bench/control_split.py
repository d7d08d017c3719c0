"""Where a MuJoCo trial's step goes, measured inside the production trial: per physics step, the engine's
`mj_step` as the trial runs it, the control law (CPG and string kernel) as the trial runs it, the copies of the
state and wrench between them, and the Python around the compiled calls (the guard's checks, the contact guard's
looks, the COM path, the set-up and result), per built-in.

    python bench/control_split.py [--spines all] [--seconds 3] [--repeats 3] [--controller NAME]

The parts are timed in a twin of the trial: worker.trial.simulation.simulate through the piecewise loop (the
one-call run of whole check intervals, worker.trial.loop.run_checked, switched off), with its compiled run
(worker.trial.loop.run_compiled) swapped for a copy that reads the CPU's time-stamp counter around each part
(the same arithmetic, so the trial's bits are unchanged: `same_distance` checks it against the production
trial, whose CPU time is `whole`; `whole_piecewise_timed` is the twin's); the counter runs in wall
time, so a part of a step longer than PREEMPTED_US (the law: plus twice a CPG update) had another process in it
and is left out of that part's mean (`parts_preempted`). The CPG alone is timed apart in a compiled loop on a
copy of the trial's network at the trial's CPG plan (`cpg_us_per_step`), so
`law - cpg` is the string kernel's. Shares are of the whole step (CPU time of the whole trial over its steps):
`control_share` = 1 - in-trial mj_step / whole (bench/trial_speed.py's figure uses a bare mj_step from the end
state instead, which costs less than the in-trial one).

Prints one JSON object (last line): {"spines": {SPINE: {"us_per_step": {"whole", "mj_step", "law", "cpg",
"strings", "copies", "python"}, "control_share", "law_share", "python_share", ...}}}, medians over --repeats
seeded random gaits after a warm-up trial.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from spinefarm.robot.morphology.registry import builtin_names, load_morphology  # noqa: E402
from spinefarm.worker.control.cpg import rk4_advance  # noqa: E402
from spinefarm.worker.control.law import STATUS_OK, law_step_world  # noqa: E402
from spinefarm.worker.trial import batch, loop  # noqa: E402
from spinefarm.worker.trial.setup import SetupCache  # noqa: E402
from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, simulate  # noqa: E402

# a part of a step this long had another process's time slice in it (the slowest mj_step measured: ~0.35 ms,
# ribbed); the law's cap adds twice a CPG update (NTRT's 0.1 s update: 100 RK4 steps at once, up to ~2 ms)
PREEMPTED_US = 1500.0


@intrinsic
def _ticks(typingctx):
    """The CPU's time-stamp counter (llvm.readcyclecounter)."""
    def codegen(context, builder, signature, args):
        fn = builder.module.declare_intrinsic("llvm.readcyclecounter", fnty=ir.FunctionType(ir.IntType(64), []))
        return builder.call(fn, [])
    return types.int64(), codegen


@njit
def _run_timed(world, cpg, strings, clock, b, n_steps, poses, ticks, caps):
    """worker.trial.loop.run_compiled with, per part p (0: copy-in + copy-out, 1: law, 2: mj_step), ticks[p] += its
    ticks and ticks[4 + p] += 1 where it took fewer ticks than caps[p] (else ticks[7] += 1: another process
    ran in it); ticks[3] += 1 (calls). Each part is kept or left out on its own, so a long step (a CPG update)
    is not left out more often for the other parts' preemptions."""
    step, m_addr, d_addr, state, columns, wrench = world
    force = strings[6][b]
    torque = strings[7][b]
    nb = poses.shape[0]
    ticks[3] += 1
    for n in range(n_steps):
        t0 = _ticks()
        for i in range(nb):
            for c in range(7):
                poses[i, c] = state[i, columns[c]]
        t1 = _ticks()
        status = law_step_world(cpg, strings, clock, b, poses)
        t2 = _ticks()
        if status != STATUS_OK:
            return status, n
        for i in range(nb):
            for c in range(3):
                wrench[i, c] = force[i, c]
                wrench[i, 3 + c] = torque[i, c]
        t3 = _ticks()
        loop._call_step(step, m_addr, d_addr)
        t4 = _ticks()
        parts = ((t1 - t0) + (t3 - t2), t2 - t1, t4 - t3)
        for p in range(3):
            if parts[p] < caps[p]:
                ticks[p] += parts[p]
                ticks[4 + p] += 1
            else:
                ticks[7] += 1
    return STATUS_OK, n_steps


@njit
def _ticks_now():
    return _ticks()


def ticks_per_us() -> float:
    """The counter's rate, against perf_counter (both wall time)."""
    _ticks_now()
    t0, k0 = time.perf_counter(), _ticks_now()
    while time.perf_counter() - t0 < 0.2:
        pass
    return (_ticks_now() - k0) / ((time.perf_counter() - t0) * 1e6)


@njit
def _cpg_loop(state, net, h, n_sub, work, out, n):
    for _ in range(n):
        rk4_advance(state, net, h, n_sub, work, out)


def cpg_us_per_step(law, repeats: int = 3000) -> float:
    """CPU µs of the CPG per physics step at the law's plan (world 0): one update's RK4 over its steps."""
    state, omega, amp, indptr, source, wc, rate, h, n_sub, scratch, out, _, _ = law.cpg
    every = int(law.clock[1][0])
    if every <= 0:
        return 0.0
    net = (omega[0], amp[0], indptr[0], source[0], wc[0], rate[0])
    s, w, o = state[0].copy(), scratch[0].copy(), out[0].copy()
    _cpg_loop(s, net, h[0], n_sub[0], w, o, 1)
    t0 = time.process_time()
    _cpg_loop(s, net, h[0], n_sub[0], w, o, repeats)
    return (time.process_time() - t0) / repeats * 1e6 / every


def one_trial(morph, u, cfg: TrialConfig, seed: int, cache: SetupCache, controller: str | None,
              caps: np.ndarray) -> dict:
    """One trial through the timed loop (caps: ticks per part beyond which a step counts as preempted)."""
    tpu = caps[3]
    ticks = np.zeros(8, dtype=np.int64)
    plain = loop.run_compiled

    def timed(world, cpg, strings, clock, b, n_steps, poses):
        return _run_timed(world, cpg, strings, clock, b, n_steps, poses, ticks, caps)
    checked = batch.checked_runner
    loop.run_compiled = timed
    batch.checked_runner = lambda engine, law: None  # the piecewise loop, whose compiled pieces are timed
    try:
        t0 = time.process_time()
        res = simulate(morph, u, cfg, seed, controller=controller, setup=cache).result
        timed_s = time.process_time() - t0
    finally:
        loop.run_compiled, batch.checked_runner = plain, checked
    t0 = time.process_time()
    reference = simulate(morph, u, cfg, seed, controller=controller, setup=cache).result  # the production loop
    whole_s = time.process_time() - t0
    steps = res.sim_time_s / res.extras["dt_s"] + round(cfg.settle_s / res.extras["dt_s"])
    copies, law_us, mj = (ticks[:3] / tpu / ticks[4:7]).tolist()  # per step, over each part's kept steps
    whole = whole_s * 1e6 / steps
    return {"whole": whole, "whole_piecewise_timed": timed_s * 1e6 / steps, "mj_step": mj, "law": law_us,
            "copies": copies,
            "python": whole - mj - law_us - copies, "compiled_calls_per_step": ticks[3] / steps,
            "parts_preempted": int(ticks[7]), "steps_timed": int(ticks[6]),
            "same_distance": res.distance_m == reference.distance_m, "distance_m": res.distance_m,
            "segment_contacts": res.extras.get("segment_contacts", "left out")}


def spine_split(name: str, seconds: float, repeats: int, controller: str | None, tpu: float) -> dict:
    from spinefarm.protocol.errors import ConfigError
    from spinefarm.worker.control.law import ControlLaw
    from spinefarm.worker.trial.episode import choose_step

    morph = load_morphology(name)
    cfg = TrialConfig(duration_s=seconds, engine="mujoco")
    try:
        choose_step(morph, cfg)
    except ConfigError:  # a string network the default step cannot take (tetraspine-hardware): the automatic one
        cfg = dataclasses.replace(cfg, auto_dt=True)
    cache = SetupCache()
    rows = []
    for r in range(repeats + 1):  # the first warms caches and compiled code
        u = random_unit_params(morph, 1 + r, controller)
        setup = cache.get(morph, cfg, controller)
        net = setup.space.network(setup.space.param_space.physical(u))
        g = setup.geom
        law = ControlLaw([net], [setup.string_tables(net)], (g.body_a, g.body_b, g.anchor_a_cm, g.anchor_b_cm),
                         len(setup.bodies), cfg.cpg_max_step_s, cfg.motor_model)
        every = max(1, round(morph.control.cpg_update_period_s / setup.dt))
        law.begin_phase(every, setup.dt, cfg.cpg_own_step_s if every == 1 else None)
        cpg = cpg_us_per_step(law)
        update_us = cpg * max(1, int(law.clock[1][0]))
        caps = np.array([PREEMPTED_US, PREEMPTED_US + 2 * update_us, PREEMPTED_US, 0]) * tpu
        caps[3] = tpu
        row = one_trial(morph, u, cfg, 1 + r, cache, controller, caps)
        row["cpg"] = cpg
        row["strings"] = row["law"] - row["cpg"]
        if r:
            rows.append(row)
    parts = ("whole", "whole_piecewise_timed", "mj_step", "law", "cpg", "strings", "copies", "python")
    med = {k: float(np.median([row[k] for row in rows])) for k in parts}
    print(f"{name}: " + ", ".join(f"{k} {v:.1f}" for k, v in med.items()) + " µs per step", file=sys.stderr)
    return {"us_per_step": med, "control_share": 1.0 - med["mj_step"] / med["whole"],
            "law_share": med["law"] / med["whole"], "python_share": med["python"] / med["whole"],
            "same_distance": all(row["same_distance"] for row in rows),
            "distance_m": [row["distance_m"] for row in rows],
            "segment_contacts": [row["segment_contacts"] for row in rows],
            "compiled_calls_per_step": float(np.median([row["compiled_calls_per_step"] for row in rows]))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spines", default="all", help="all built-ins, or names separated by commas")
    ap.add_argument("--seconds", type=float, default=3.0, help="simulated seconds per trial (default 3)")
    ap.add_argument("--repeats", type=int, default=3, help="random gaits per spine after a warm-up (default 3)")
    ap.add_argument("--controller", default=None, help="controller space (default: each spine's own)")
    args = ap.parse_args()
    names = builtin_names() if args.spines == "all" else args.spines.split(",")
    tpu = ticks_per_us()
    spines = {n: spine_split(n, args.seconds, args.repeats, args.controller, tpu) for n in names}
    print(json.dumps({"spines": spines, "seconds": args.seconds, "repeats": args.repeats,
                      "controller": args.controller}))


if __name__ == "__main__":
    main()
