"""Per-step cost of the 12-segment Tetraspine trial loop against a bare stepSimulation, and the two tiers.

Prints one JSON object (last line): wall seconds per simulated second at the default step, the
split per step (state read, control = CPG, string law, force write, stepSimulation) in
microseconds, and step_to_bare_ratio = whole step / bare stepSimulation of the same bodies with no
strings and no control. Both scenes are measured in this one run, interleaved, so machine noise
affects them alike.

The tiers: whole trials (the production loop, set-up reused) on Bullet and on MuJoCo, each at its
default step, interleaved: CPU seconds per simulated second of each and `mujoco_speedup` = Bullet's
over MuJoCo's (also without segment-segment contacts, as a 2 ms screen, and against Bullet at 0.25 ms,
the step where Bullet is about as accurate as MuJoCo at its default); MuJoCo's split (a bare mj_step; the
rest = CPG, strings and the fused loop); `engine_step_ratio`, Bullet's stepSimulation over a bare mj_step
(the ceiling of mujoco_speedup at equal steps, were CPG, strings and loop free); `engine_step_ratio_2ms`,
the same against a bare 2 ms mj_step per simulated millisecond; `mujoco_speedup_bound_2ms`, the most a 2 ms
default step could give (a bare 2 ms mj_step plus the CPG at one RK4 step per 2 ms, `cpg_us_per_sim_ms`;
strings and loop free); and `setup_s_per_trial`: a trial's set-up built fresh (as before set-up reuse)
against reused from the worker's SetupCache, per engine.

    python bench/trial_speed.py [--morphology tetraspine] [--steps 3000] [--repeats 3] [--tier-seconds 10]
                                [--moving RUN.h5]

With --spines (all, or names separated by commas) it measures whole trials only, per spine: seeded random
gaits at each engine's default step, interleaved, with `bullet_cpu_s_per_sim_s`, `mujoco_cpu_s_per_sim_s`
(segment-segment contacts by the default "auto": left out while the contact guard finds none can form, the
trial run again with them when one could; `mujoco_reruns` lists those), `mujoco_speedup`, and for comparison
MuJoCo with them modelled by MuJoCo's own search ("scene"), left out ("off") and modelled only for the rod pairs
the structure lets come within reach ("reach", `mujoco_reach_rod_pairs` counts them), with the pyramidal friction
cone (`mujoco_pyramidal_cone`, the default before the elliptic one), every trial's distance, and
`control_share`: the control law and the loop over MuJoCo's whole step (1 - a bare mj_step from the trial's end
state over the whole step; `mujoco_split_us_per_step`), with `control_law_share` the law alone (CPG and strings
timed apart on the end pose), and `guard_check_us`: one guard check of one world on the end pose, exact and
compiled (worker.trial.guard):

    python bench/trial_speed.py --spines all [--tier-seconds 10] [--repeats 3]

With --settled SETTLE_S, MuJoCo trials of --tier-seconds after a settle phase of SETTLE_S, each starting from the
settle end kept by the set-up (worker.trial.settled) against each settling again, interleaved (CPU s per trial):

    python bench/trial_speed.py --settled 1 --tier-seconds 3 [--morphology tetraspine] [--repeats 5]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time

import numpy as np

from spinefarm.robot.bodies import build_bodies, build_strings
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.scene import GroundSpec
from spinefarm.robot.spaces import controller_space
from spinefarm.worker.control.cpg import CpgIntegrator
from spinefarm.worker.engines.bullet import BulletPhysics
from spinefarm.worker.sim import strings as sk
from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, string_tables


def measure(morph_name: str, steps: int, warmup: int, seed: int) -> dict:
    morph = load_morphology(morph_name)
    cfg = TrialConfig()
    dt = cfg.step_s
    space = controller_space(morph)
    net = space.network(space.param_space.from_unit(random_unit_params(morph, seed)))
    bodies = build_bodies(morph.structure)
    geom = build_strings(morph.structure, bodies)
    sparams, sstate = string_tables(morph, geom.start_length_cm, {int(s): n for n, s in enumerate(net.node_string)})
    ground = GroundSpec(friction=morph.ground_friction)
    scene = BulletPhysics(bodies, ground, dt).worlds[0]  # one pybullet world: the parts of a step, timed apart
    bare = BulletPhysics(bodies, ground, dt).worlds[0]
    cpg = CpgIntegrator(net, cfg.cpg_max_step_s)
    nb = len(bodies)
    bank = sk.StringBank(nb, geom.body_a, geom.body_b, geom.anchor_a_cm, geom.anchor_b_cm, sparams, sstate)
    period = morph.control.cpg_update_period_s
    every = max(1, round(period / dt))
    t = {"read": 0.0, "control": 0.0, "strings": 0.0, "write": 0.0, "step": 0.0, "bare_step": 0.0}
    clock = time.perf_counter
    for n in range(warmup + steps):
        t0 = clock()
        poses = scene.read_poses()
        t1 = clock()
        if (n + 1) % every == 0:
            cpg.advance(period)
        t2 = clock()
        bank.step(poses, cpg.output_cm_s, dt, sk.MOTOR_PHYSICAL)
        t3 = clock()
        scene.apply_wrenches(bank.force, bank.torque)
        t4 = clock()
        scene.step()
        t5 = clock()
        bare.step()
        t6 = clock()
        if n >= warmup:
            for key, dtm in zip(t, (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4, t6 - t5), strict=True):
                t[key] += dtm
    scene.close()
    bare.close()
    per_step_us = {k: v / steps * 1e6 for k, v in t.items()}
    whole = sum(v for k, v in per_step_us.items() if k != "bare_step")
    return {"per_step_us": per_step_us, "whole_step_us": whole,
            "step_to_bare_ratio": whole / per_step_us["bare_step"],
            # stricter: against this scene's own engine step (the bare scene has other contacts)
            "step_to_engine_ratio": whole / per_step_us["step"],
            "wall_s_per_sim_s": whole * 1e-6 / dt, "n_bodies": nb, "n_strings": len(bank.params),
            "n_cpg_nodes": net.n_nodes, "n_couplings": net.n_couplings, "dt_s": dt}


def _tier_configs(seconds: float, mujoco_options: dict) -> dict[str, TrialConfig]:
    off = {**mujoco_options, "segment_contacts": "off"}
    modelled = {**mujoco_options, "segment_contacts": "scene"}
    return {"bullet": TrialConfig(duration_s=seconds, engine="bullet"),
            "mujoco": TrialConfig(duration_s=seconds, engine="mujoco", engine_options=mujoco_options),
            "mujoco_segment_contacts_modelled": TrialConfig(duration_s=seconds, engine="mujoco",
                                                            engine_options=modelled),
            "mujoco_segment_contacts_off": TrialConfig(duration_s=seconds, engine="mujoco", engine_options=off),
            "mujoco_screen_2ms": TrialConfig(duration_s=seconds, engine="mujoco", dt_s=2e-3, engine_options=off),
            "bullet_0.25ms": TrialConfig(duration_s=seconds, engine="bullet", dt_s=2.5e-4)}


def _bare_mj_step_us(scene, steps: int = 200) -> float:
    """A bare mj_step from the trial's last state with its last string wrenches held, in CPU time (MuJoCo's own
    timers count wall time, which a shared machine inflates)."""
    import mujoco

    t1 = time.process_time()
    for _ in range(steps):
        mujoco.mj_step(scene.model, scene.data[0])
    return (time.process_time() - t1) / steps * 1e6


def tiers(morph_name: str, seconds: float, repeats: int, mujoco_options: dict,
          gaits: list[np.ndarray] | None = None, controller: str | None = None) -> dict:
    """CPU s per simulated second of whole trials, interleaved: both engines at their default steps, and for
    context MuJoCo with segment-segment contacts modelled throughout ("scene"; the default "auto" leaves
    them out while no segment comes near, same bits), without them, MuJoCo as a screen (2 ms, no
    segment-segment contacts) and Bullet at 0.25 ms (about MuJoCo's default-step accuracy, docs/accuracy.md).
    gaits: unit parameter vectors (of `controller`'s space) to run, one per round after a warm-up round;
    default: seeded random ones."""
    from spinefarm.worker.trial.setup import SetupCache
    from spinefarm.worker.trial.simulation import simulate

    morph = load_morphology(morph_name)
    configs = _tier_configs(seconds, mujoco_options)
    caches = {e: SetupCache() for e in configs}
    cpu: dict[str, list[float]] = {e: [] for e in configs}
    mj_step_us, mj_step_2ms_us, dts, contacts, fallbacks = [], [], {}, [], []
    distances: dict[str, list[float]] = {e: [] for e in configs}
    rounds = repeats + 1 if gaits is None else len(gaits) + 1
    for r in range(rounds):  # the first round warms caches and compiled code
        u = random_unit_params(morph, 7 + r, controller) if gaits is None else gaits[max(0, r - 1)]
        for name, cfg in configs.items():
            t0 = time.process_time()
            res = simulate(morph, u, cfg, 7 + r, controller=controller, setup=caches[name]).result
            el = time.process_time() - t0
            dts[name] = res.extras["dt_s"]
            if name == "mujoco" and r:
                fallbacks.append(res.extras.get("segment_contacts", "left out"))
            if r:
                cpu[name].append(el / res.sim_time_s)
                distances[name].append(res.distance_m)
            if name in ("mujoco", "mujoco_screen_2ms") and r:
                ran = cfg if "segment_contacts" not in res.extras else dataclasses.replace(  # re-run with them
                    cfg, engine_options={**cfg.engine_options, "segment_contacts": "scene"})
                scene = caches[name].get(morph, ran, controller)._scene
                if name == "mujoco":
                    contacts.append(scene.contact_count())
                (mj_step_us if name == "mujoco" else mj_step_2ms_us).append(_bare_mj_step_us(scene))
    med = {e: float(np.median(v)) for e, v in cpu.items()}
    mj = float(np.median(mj_step_us))
    return {"tier_seconds": seconds, "cpu_s_per_sim_s": med, "dt_s": dts, "mujoco_options": mujoco_options,
            "mujoco_split_us_per_step": {"whole": med["mujoco"] * 1e6 * dts["mujoco"], "mj_step": mj,
                                         "rest_cpg_strings_loop": med["mujoco"] * 1e6 * dts["mujoco"] - mj},
            "mj_step_2ms_screen_us": float(np.median(mj_step_2ms_us)),
            "mujoco_contacts_at_end": contacts, "mujoco_speedup": med["bullet"] / med["mujoco"],
            "mujoco_speedup_segment_contacts_off": med["bullet"] / med["mujoco_segment_contacts_off"],
            "mujoco_speedup_segment_contacts_modelled": med["bullet"] / med["mujoco_segment_contacts_modelled"],
            "mujoco_segment_contacts_auto": fallbacks,
            "mujoco_screen_speedup": med["bullet"] / med["mujoco_screen_2ms"],
            "speedup_at_equal_accuracy": med["bullet_0.25ms"] / med["mujoco"],
            "cpu_s_per_sim_s_all": {e: [round(x, 4) for x in v] for e, v in cpu.items()},
            "distance_m": {e: [round(x, 4) for x in v] for e, v in distances.items()}}


SPEED_TIERS = {"bullet": ("bullet", {}), "mujoco": ("mujoco", {}),
               "mujoco_segment_contacts_scene": ("mujoco", {"segment_contacts": "scene"}),
               "mujoco_segment_contacts_off": ("mujoco", {"segment_contacts": "off"}),
               "mujoco_segment_contacts_reach": ("mujoco", {"segment_contacts": "reach"}),
               "mujoco_pyramidal_cone": ("mujoco", {"cone": "pyramidal"})}  # the default before the elliptic


def spine_speeds(morph_name: str, seconds: float, repeats: int) -> dict:
    """CPU s per simulated s of whole trials (set-up reused, a first round to warm up) at each engine's
    default step: Bullet, MuJoCo as it runs by default, and MuJoCo's segment-segment contacts both ways."""
    from spinefarm.protocol.errors import ConfigError
    from spinefarm.worker.trial.episode import choose_step
    from spinefarm.worker.trial.setup import SetupCache
    from spinefarm.worker.trial.simulation import simulate

    morph = load_morphology(morph_name)
    configs = {name: TrialConfig(duration_s=seconds, engine=engine, engine_options=options)
               for name, (engine, options) in SPEED_TIERS.items()}
    try:
        choose_step(morph, configs["bullet"])
    except ConfigError:  # a string network the default step cannot take (tetraspine-hardware): the automatic one
        configs = {name: dataclasses.replace(cfg, auto_dt=True) for name, cfg in configs.items()}
    caches = {name: SetupCache() for name in configs}
    cpu: dict[str, list[float]] = {name: [] for name in configs}
    distance: dict[str, list[float]] = {name: [] for name in configs}
    reruns, mj_step_us, law_us, guard_us = [], [], [], []
    for r in range(repeats + 1):
        u = random_unit_params(morph, 1 + r)
        for name, cfg in configs.items():
            t0 = time.process_time()
            res = simulate(morph, u, cfg, 1 + r, setup=caches[name]).result
            if r:
                cpu[name].append((time.process_time() - t0) / res.sim_time_s)
                distance[name].append(round(res.distance_m, 5))
                if name == "mujoco" and "segment_contacts" in res.extras:
                    reruns.append(res.extras["segment_contacts"])
                if name == "mujoco":  # the engine's own step and the law's, from where the trial ended
                    ran = cfg if "segment_contacts" not in res.extras else dataclasses.replace(
                        cfg, engine_options={**cfg.engine_options, "segment_contacts": "scene"})
                    setup = caches[name].get(morph, ran, None)
                    mj_step_us.append(_bare_mj_step_us(setup._scene))
                    law_us.append(law_step_us(setup, u, cfg))
                    guard_us.append(guard_check_us(setup, u, cfg))
    med = {name: float(np.median(v)) for name, v in cpu.items()}
    whole_us = med["mujoco"] * 1e6 * choose_step(morph, configs["mujoco"])
    split = {"whole": whole_us, "mj_step": float(np.median(mj_step_us)), "control_law": float(np.median(law_us))}
    print(f"{morph_name}: bullet {med['bullet']:.3f}, mujoco {med['mujoco']:.3f} CPU s per simulated s",
          file=sys.stderr)
    return {"dt_s": {name: choose_step(morph, cfg) for name, cfg in configs.items()},
            "bullet_cpu_s_per_sim_s": med["bullet"], "mujoco_cpu_s_per_sim_s": med["mujoco"],
            "mujoco_speedup": med["bullet"] / med["mujoco"],
            # control law (CPG and strings) and loop over MuJoCo's whole step; the law alone beside it
            "control_share": (whole_us - split["mj_step"]) / whole_us,
            "control_law_share": split["control_law"] / whole_us, "mujoco_split_us_per_step": split,
            # one guard check of one world (every check_every_s), the exact numpy check and its compiled fast path
            "guard_check_us": {k: float(np.median([g[k] for g in guard_us])) for k in ("exact", "compiled")},
            "mujoco_segment_contacts_scene_cpu_s_per_sim_s": med["mujoco_segment_contacts_scene"],
            "mujoco_segment_contacts_off_cpu_s_per_sim_s": med["mujoco_segment_contacts_off"],
            "mujoco_segment_contacts_reach_cpu_s_per_sim_s": med["mujoco_segment_contacts_reach"],
            "mujoco_speedup_segment_contacts_reach": med["bullet"] / med["mujoco_segment_contacts_reach"],
            "mujoco_reach_rod_pairs": reach_pairs(morph, configs["mujoco_segment_contacts_reach"]),
            "mujoco_reruns": reruns, "cpu_s_per_sim_s_all": {k: [round(x, 4) for x in v] for k, v in cpu.items()},
            "distance_m": distance}


def law_step_us(setup, u: np.ndarray, cfg: TrialConfig, steps: int = 2000) -> float:
    """CPU µs of one step of the control law (CPG at the trial's own CPG step, strings) on a fixed pose,
    a fresh law of parameter set u on the set-up's robot."""
    from spinefarm.worker.control.law import ControlLaw

    net = setup.space.network(setup.space.param_space.physical(u))
    g = setup.geom
    law = ControlLaw([net], [setup.string_tables(net)], (g.body_a, g.body_b, g.anchor_a_cm, g.anchor_b_cm),
                     len(setup.bodies), cfg.cpg_max_step_s, cfg.motor_model)
    every = max(1, round(setup.morph.control.cpg_update_period_s / setup.dt))
    law.begin_phase(every, setup.dt, cfg.cpg_own_step_s if every == 1 else None)
    poses, active = setup._scene.read_poses()[:1].copy(), np.ones(1, dtype=bool)
    law.step(poses, active)  # compiled before timing
    t0 = time.process_time()
    for _ in range(steps):
        law.step(poses, active)
    return (time.process_time() - t0) / steps * 1e6


def guard_check_us(setup, u: np.ndarray, cfg: TrialConfig, repeats: int = 500) -> dict:
    """CPU µs of one guard check on the trial's end pose: the exact check and the compiled fast path."""
    from spinefarm.worker.trial import guard
    from spinefarm.worker.trial.episode import STRETCH_BASE_MIN_CM, check_state

    net = setup.space.network(setup.space.param_space.physical(u))
    _, sstate = setup.string_tables(net)
    poses = setup._scene.read_poses()[0].copy()
    start = setup.geom.start_length_cm
    boxes, limits, base = guard.level_boxes(setup.terrain), guard.limits(cfg), np.maximum(start, STRETCH_BASE_MIN_CM)
    lprev = sstate[:, sk.S_LPREV].copy()
    guard.clearly_sane(poses, poses[:, :3], setup.masses, lprev, base, 0.01, boxes, limits)  # compiled first
    t0 = time.process_time()
    for _ in range(repeats):
        check_state(poses, poses[:, :3], setup.masses, sstate, start, 0.01, cfg, setup.terrain)
    t1 = time.process_time()
    for _ in range(repeats):
        guard.clearly_sane(poses, poses[:, :3], setup.masses, lprev, base, 0.01, boxes, limits)
    return {"exact": (t1 - t0) / repeats * 1e6, "compiled": (time.process_time() - t1) / repeats * 1e6}


def reach_pairs(morph, cfg: TrialConfig) -> dict:
    """How many rod pairs of different segments "reach" (cfg's segment_contacts) models, of all of them."""
    from spinefarm.worker.trial.setup import TrialSetup

    setup = TrialSetup(morph, cfg, None)
    sizes = [len(b.rods) for b in setup.bodies]
    total = sum(sizes[a] * sizes[b] for a in range(len(sizes)) for b in range(a + 1, len(sizes)))
    return {"modelled": len(setup.rod_pairs()), "of": total}


def settled_cost(morph_name: str, seconds: float, settle_s: float, repeats: int) -> dict:
    """CPU s per MuJoCo trial (settle_s then seconds of locomotion, set-up reused, seeded random gaits),
    interleaved: every trial starting from the kept settle end (worker.trial.settled) against every trial settling."""
    from spinefarm.worker.trial.setup import SetupCache
    from spinefarm.worker.trial.simulation import simulate

    morph = load_morphology(morph_name)
    cfg = TrialConfig(duration_s=seconds, settle_s=settle_s, engine="mujoco")
    caches = {"settled_start": SetupCache(), "settle_every_trial": SetupCache()}
    cpu: dict[str, list[float]] = {name: [] for name in caches}
    distance: dict[str, list[float]] = {name: [] for name in caches}
    for r in range(repeats + 1):  # the first round warms compiled code and keeps the settle end
        u = random_unit_params(morph, 1 + r)
        for name, cache in caches.items():
            if name == "settle_every_trial":
                cache.get(morph, cfg, None).settled.size = 0  # keeps nothing
            t0 = time.process_time()
            res = simulate(morph, u, cfg, 1 + r, setup=cache).result
            if r:
                cpu[name].append(time.process_time() - t0)
                distance[name].append(res.distance_m)
    med = {name: float(np.median(v)) for name, v in cpu.items()}
    return {"morphology": morph_name, "settle_s": settle_s, "duration_s": seconds, "cpu_s_per_trial": med,
            "settle_every_trial_over_settled_start": med["settle_every_trial"] / med["settled_start"],
            "same_distances": distance["settled_start"] == distance["settle_every_trial"],
            "cpu_s_per_trial_all": {k: [round(x, 4) for x in v] for k, v in cpu.items()}}


def cpg_cost(morph_name: str, seed: int, updates: int = 5000) -> dict:
    """CPU µs of the compiled CPG kernel per simulated millisecond: at the morphology's control period with
    the default sub-steps (as trials run it: 1 ms on NTRT's networks), and as one RK4 step per 2 ms (the
    least a 2 ms physics step could spend on it)."""
    from spinefarm.worker.control.cpg import rk4_advance

    morph = load_morphology(morph_name)
    space = controller_space(morph)
    net = space.network(space.param_space.from_unit(random_unit_params(morph, seed)))
    out = {}
    plans = (("as_run", morph.control.cpg_update_period_s, TrialConfig().cpg_max_step_s),
             ("one_rk4_per_2ms", 2e-3, 2e-3))
    for label, period, max_step in plans:
        cpg = CpgIntegrator(net, max_step)
        h, n = cpg.plan(period)
        kernel = cpg.kernel_arrays()
        rk4_advance(cpg.state, kernel, h, n, cpg.work, cpg.output_cm_s)  # compiled before timing
        t0 = time.process_time()
        for _ in range(updates):
            rk4_advance(cpg.state, kernel, h, n, cpg.work, cpg.output_cm_s)
        out[label] = (time.process_time() - t0) / updates * 1e6 / (period * 1e3)
    return out


def best_gaits(path: str, count: int, apart: float = 0.1) -> tuple[list[np.ndarray], str | None]:
    """The unit parameter vectors of a run file's `count` farthest complete trials that differ from each
    other by more than `apart` in some parameter (a converged search's best are one gait many times), and
    the run's controller."""
    import h5py

    with h5py.File(path, "r") as f:
        t = f["trials"]
        distance = np.where(t["status"][:] == b"complete", t["distance_m"][:], -np.inf)
        units = t["params_unit"][:]
        controller = str(f.attrs["controller"]) if f.attrs.get("controller") else None
    chosen: list[np.ndarray] = []
    for i in np.argsort(-distance):
        if not np.isfinite(distance[i]) or len(chosen) == count:
            break
        if all(np.max(np.abs(units[i] - u)) > apart for u in chosen):
            chosen.append(units[i])
    return chosen, controller


def setup_cost(morph_name: str, repeats: int) -> dict:
    """Set-up of one trial (a 1-step trial's wall time): built fresh against reused, per engine."""
    from spinefarm.worker.trial.setup import SetupCache
    from spinefarm.worker.trial.simulation import simulate

    morph = load_morphology(morph_name)
    out = {}
    for engine in ("bullet", "mujoco"):
        cfg = TrialConfig(duration_s=1e-3, engine=engine, check_every_s=1e-3)
        cache = SetupCache()
        fresh, reused = [], []
        for r in range(repeats + 1):
            u = random_unit_params(morph, r)
            t0 = time.perf_counter()
            simulate(morph, u, cfg, r)
            t1 = time.perf_counter()
            simulate(morph, u, cfg, r, setup=cache)
            t2 = time.perf_counter()
            if r:
                fresh.append(t1 - t0)
                reused.append(t2 - t1)
        out[engine] = {"fresh_s": float(np.median(fresh)), "reused_s": float(np.median(reused))}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--morphology", default="tetraspine")
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--warmup", type=int, default=500)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--tier-seconds", type=float, default=10.0, help="simulated seconds per tier trial")
    ap.add_argument("--mujoco-options", default="{}", help="MuJoCo engine options as JSON (default: its defaults)")
    ap.add_argument("--moving", metavar="RUN.h5", help="also the tiers on 3 of the best gaits of this run file, "
                    "all different (gaits that move: their segments come nearer each other than random ones')")
    ap.add_argument("--spines", help="whole trials per spine only: 'all' (every built-in) or names, comma-separated")
    ap.add_argument("--settled", metavar="SETTLE_S", type=float,
                    help="MuJoCo trials of --tier-seconds after a settle of SETTLE_S only: started from the kept "
                         "settle end against settling in every trial")
    args = ap.parse_args()
    if args.settled:
        print(json.dumps({"benchmark": "trial_speed", "repeats": args.repeats,
                          **settled_cost(args.morphology, args.tier_seconds, args.settled, args.repeats)}))
        return
    if args.spines:
        from spinefarm.robot.morphology.registry import builtin_names

        names = builtin_names() if args.spines == "all" else args.spines.split(",")
        t0 = time.time()
        out = {"benchmark": "trial_speed", "tier_seconds": args.tier_seconds, "repeats": args.repeats,
               "spines": {name: spine_speeds(name, args.tier_seconds, args.repeats) for name in names}}
        print(json.dumps({**out, "wall_s": time.time() - t0}))
        return
    runs = [measure(args.morphology, args.steps, args.warmup, seed=7 + r) for r in range(args.repeats)]
    best = min(runs, key=lambda r: r["step_to_bare_ratio"])
    tier = tiers(args.morphology, args.tier_seconds, args.repeats, json.loads(args.mujoco_options))
    out = {"benchmark": "trial_speed", "morphology": args.morphology, **best,
           "step_to_bare_ratio_all": [round(r["step_to_bare_ratio"], 3) for r in runs],
           "mujoco_speedup": tier["mujoco_speedup"],
           # the most mujoco_speedup could be at equal steps if CPG, strings and loop cost nothing: Bullet's
           # stepSimulation in the controlled scene over a bare mj_step
           "engine_step_ratio": best["per_step_us"]["step"] / tier["mujoco_split_us_per_step"]["mj_step"],
           "tiers": tier,
           # a 2 ms default step at its cheapest: bare mj_step (segment-segment contacts off) and one RK4 CPG
           # step per 2 ms, strings and loop free; an upper bound of mujoco_speedup had 2 ms met the 1 % bar
           "cpg_us_per_sim_ms": cpg_cost(args.morphology, seed=7),
           "engine_step_ratio_2ms": best["per_step_us"]["step"] / (tier["mj_step_2ms_screen_us"] / 2),
           "setup_s_per_trial": setup_cost(args.morphology, args.repeats)}
    cpg_2ms = out["cpg_us_per_sim_ms"]["one_rk4_per_2ms"]
    out["mujoco_speedup_bound_2ms"] = tier["cpu_s_per_sim_s"]["bullet"] * 1e3 / (tier["mj_step_2ms_screen_us"] / 2
                                                                              + cpg_2ms)
    if args.moving:
        gaits, controller = best_gaits(args.moving, 3)
        moving = tiers(args.morphology, args.tier_seconds, args.repeats, json.loads(args.mujoco_options), gaits,
                       controller)
        out["moving_gaits"] = {"run": args.moving, "controller": controller, **moving}
    print(json.dumps(out))


if __name__ == "__main__":
    main()
