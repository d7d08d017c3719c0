"""Per-step cost of the 12-segment Tetraspine trial loop against a bare stepSimulation.

Prints one JSON object (last line): wall seconds per simulated second at the default step, the
split per step (state read, control = CPG, string law, force write, stepSimulation) in
microseconds, and step_to_bare_ratio = whole step / bare stepSimulation of the same bodies with no
strings and no control. Both scenes are measured in this one run, interleaved, so machine noise
affects them alike.

    python bench/trial_speed.py [--morphology tetraspine] [--steps 3000] [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import time

from robot.bodies import build_bodies, build_strings
from robot.morphology.registry import load_morphology
from robot.scene import GroundSpec
from worker.control.cpg import CpgIntegrator
from worker.engines.bullet import BulletPhysics
from worker.sim import strings as sk
from worker.trial import TrialConfig, random_unit_params, string_tables


def measure(morph_name: str, steps: int, warmup: int, seed: int) -> dict:
    morph = load_morphology(morph_name)
    cfg = TrialConfig()
    dt = cfg.dt_s
    space = morph.controller_space()
    net = space.network(space.param_space.from_unit(random_unit_params(morph, seed)))
    bodies = build_bodies(morph.structure)
    geom = build_strings(morph.structure, bodies)
    sparams, sstate = string_tables(morph, geom.start_length_cm, {int(s): n for n, s in enumerate(net.node_string)})
    ground = GroundSpec(friction=morph.ground_friction)
    scene = BulletPhysics(bodies, ground, dt)
    bare = BulletPhysics(bodies, ground, dt)
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--morphology", default="tetraspine")
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--warmup", type=int, default=500)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    runs = [measure(args.morphology, args.steps, args.warmup, seed=7 + r) for r in range(args.repeats)]
    best = min(runs, key=lambda r: r["step_to_bare_ratio"])
    out = {"benchmark": "trial_speed", "morphology": args.morphology, **best,
           "step_to_bare_ratio_all": [round(r["step_to_bare_ratio"], 3) for r in runs]}
    print(json.dumps(out))


if __name__ == "__main__":
    main()
