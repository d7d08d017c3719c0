"""Where MuJoCo and Bullet part on one seeded gait: the same trial on both engines, sampled as it runs.

Prints one JSON object: the model each engine was actually given (per-segment mass, inertia, friction of
the terrain contacts), and every `--every` seconds per engine the robot's COM, the segments' heights,
the terrain contacts (count, summed normal and tangential force, how many slide at the friction limit)
and the segment-segment contacts (count, summed normal force); then the distance in each. MuJoCo runs
with its segment-segment contacts modelled throughout ("scene"), as Bullet's are, and both run
step by step (the recording loop), so the samples see every step.

    python bench/tier_diff.py ribbed --seed 3 --duration 2
    python bench/tier_diff.py ribbed --seed 3 --mujoco-options '{"contact_geometry": "cylinders"}'
    python bench/tier_diff.py tetraspine --seed 3 --settle 1 --duration 3 --every 0.5
"""

from __future__ import annotations

import argparse
import json
import time

import mujoco
import numpy as np
import pybullet as pb

from spinefarm.worker.engines.bullet import BulletPhysics
from spinefarm.worker.engines.mujoco import MujocoPhysics

SLIP_FRACTION = 0.98  # a contact whose tangential force is this share of mu * normal is sliding


def _summary(rows: list[tuple[int, int, float, float, float, float]], n_bodies: int) -> dict:
    """rows (segment, other segment or -1 for the terrain, normal force, tangential force, effective mu,
    signed distance cm) -> terrain and segment-segment sums over the contacts that carry force."""
    rows = [r for r in rows if r[2] > 0]  # Bullet also reports points within its breaking threshold
    ground = [r for r in rows if r[1] < 0]
    between = [r for r in rows if r[1] >= 0]
    per_segment = np.bincount([r[0] for r in ground], minlength=n_bodies)
    return {"ground_contacts": len(ground), "segments_on_ground": int((per_segment > 0).sum()),
            "ground_normal": float(sum(r[2] for r in ground)),
            "ground_tangential": float(sum(r[3] for r in ground)),
            "ground_sliding": sum(1 for r in ground if r[3] >= SLIP_FRACTION * r[4] * r[2]),
            "ground_depth_max_cm": float(max((-r[5] for r in ground), default=0.0)),
            "segment_contacts": len(between), "segment_normal": float(sum(r[2] for r in between)),
            "segment_depth_max_cm": float(max((-r[5] for r in between), default=0.0))}


class _Sampler:
    """Samples the state every `every` steps after the engine's step: mixed in ahead of an engine class, whose
    constructor and step() it wraps."""

    every = 1

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.samples, self._n = [], 0

    def step(self, active=None) -> None:
        super().step(active)
        self._n += 1
        self._sample(self._n)

    def _sample(self, steps: int) -> None:
        if steps % self.every:
            return
        poses = self.read_poses()[0]
        self.samples.append({"t_s": round(steps * self.dt_s, 9),
                             "com_xz_cm": [float(v) for v in poses[:, [0, 2]].mean(0)],
                             "heights_cm": [round(float(v), 3) for v in poses[:, 1]],
                             "positions_cm": poses[:, :3].round(4).tolist(),
                             **_summary(self.contacts(), len(poses))})


class BulletSampled(_Sampler, BulletPhysics):
    def contacts(self) -> list[tuple[int, int, float, float, float, float]]:
        w = self.worlds[0]
        index = {bid: i for i, bid in enumerate(w.body_ids)}
        rows = []
        for c in pb.getContactPoints(physicsClientId=w.client):
            a, b = index.get(c[1], -1), index.get(c[2], -1)
            mu = pb.getDynamicsInfo(c[1], -1, physicsClientId=w.client)[1] * pb.getDynamicsInfo(
                c[2], -1, physicsClientId=w.client)[1]
            a, b = (b, a) if a < 0 else (a, b)
            rows.append((a, b, c[9], float(np.hypot(c[10], c[12])), mu, c[8]))
        return rows

    def model_facts(self) -> list[dict]:
        w = self.worlds[0]
        out = []
        for bid in w.body_ids:
            info = pb.getDynamicsInfo(bid, -1, physicsClientId=w.client)
            out.append({"mass_kg": info[0], "inertia_kg_cm2": list(info[2]), "friction": info[1],
                        "rolling_friction": info[6], "spinning_friction": info[7]})
        # (pybullet cannot list a maximal-coordinate compound's shapes; they are the rods' cylinders)
        return out


class MujocoSampled(_Sampler, MujocoPhysics):
    def contacts(self) -> list[tuple[int, int, float, float, float, float]]:
        m, d = self.model, self.data[0]
        f = np.zeros(6)
        rows = []
        for i in range(d.ncon):
            c = d.contact[i]
            if c.exclude:
                continue
            mujoco.mj_contactForce(m, d, i, f)
            a, b = int(m.geom_bodyid[c.geom1]) - 1, int(m.geom_bodyid[c.geom2]) - 1  # body 0 is the world
            a, b = (b, a) if a < 0 else (a, b)
            rows.append((a, b, float(f[0]), float(np.hypot(f[1], f[2])), float(c.friction[0]), float(c.dist)))
        return rows

    def model_facts(self) -> list[dict]:
        m = self.model
        out = []
        for b in range(1, m.nbody):
            geoms = np.flatnonzero(m.geom_bodyid == b)
            kinds = {}
            for g in geoms:
                name = {mujoco.mjtGeom.mjGEOM_CAPSULE: "capsule", mujoco.mjtGeom.mjGEOM_SPHERE: "end sphere",
                        mujoco.mjtGeom.mjGEOM_CYLINDER: "cylinder"}.get(int(m.geom_type[g]), str(m.geom_type[g]))
                kinds[name] = kinds.get(name, 0) + 1
            out.append({"mass_kg": float(m.body_mass[b]), "inertia_kg_cm2": m.body_inertia[b].tolist(),
                        "friction_vs_terrain": float(m.geom_friction[0, 0]), "shapes": kinds})
        return out


def run(spine: str, engine: str, seed: int, duration_s: float, settle_s: float, every_s: float,
        options: dict, controller: str | None) -> dict:
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, simulate

    morph = load_morphology(spine)
    cls = BulletSampled if engine == "bullet" else MujocoSampled
    built: list = []

    def factory(*args, **kwargs):
        eng = cls(*args, **kwargs)
        eng.every = max(1, round(every_s / eng.dt_s))
        built.append((eng, eng.model_facts()))
        return eng

    cfg = TrialConfig(duration_s=duration_s, settle_s=settle_s, engine=engine, engine_options=options,
                      record_every_s=every_s)  # recording: the step-by-step loop, so step() sees every step
    t0 = time.process_time()
    out = simulate(morph, random_unit_params(morph, seed, controller=controller), cfg, seed,
                   controller=controller, scene_factory=factory)
    eng, facts = built[-1]
    r = out.result
    moving = [x for x in eng.samples if x["t_s"] > settle_s]  # after the settle: the gait's contacts
    return {"engine": engine, "options": options, "status": str(r.status), "distance_m": r.distance_m,
            "mean_segments_on_ground": float(np.mean([x["segments_on_ground"] for x in moving])) if moving else None,
            "mean_ground_contacts": float(np.mean([x["ground_contacts"] for x in moving])) if moving else None,
            "mean_segment_contacts": float(np.mean([x["segment_contacts"] for x in moving])) if moving else None,
            "cpu_s": time.process_time() - t0, "model": facts[0], "model_same_for_all_segments": all(
                f == facts[0] for f in facts), "samples": eng.samples}


def main() -> None:
    from spinefarm.cli import checks  # an argparse type: seeds are whole numbers >= 0

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("spine")
    ap.add_argument("--seed", type=checks.seed, default=1, help="random parameter set (as bench/tier_agreement.py's)")
    ap.add_argument("--duration", type=float, default=2.0)
    ap.add_argument("--settle", type=float, default=0.0)
    ap.add_argument("--every", type=float, default=0.1, help="sample period (s)")
    ap.add_argument("--controller", default=None)
    ap.add_argument("--mujoco-options", default="{}")
    ap.add_argument("--bullet-options", default="{}")
    args = ap.parse_args()
    mj = {"segment_contacts": "scene", **json.loads(args.mujoco_options)}
    runs = [run(args.spine, "bullet", args.seed, args.duration, args.settle, args.every,
                json.loads(args.bullet_options), args.controller),
            run(args.spine, "mujoco", args.seed, args.duration, args.settle, args.every, mj, args.controller)]
    b, m = runs
    n = min(len(b["samples"]), len(m["samples"]))
    apart = [float(np.hypot(*np.subtract(b["samples"][i]["com_xz_cm"], m["samples"][i]["com_xz_cm"])))
             for i in range(n)]
    # root mean square over segments of how far each segment's COM is from its place in the other engine
    bodies_apart = [float(np.sqrt(np.mean(np.sum(np.subtract(b["samples"][i]["positions_cm"],
                                                             m["samples"][i]["positions_cm"]) ** 2, axis=1))))
                    for i in range(n)]
    print(json.dumps({"benchmark": "tier_diff", "spine": args.spine, "seed": args.seed, "settle_s": args.settle,
                      "duration_s": args.duration, "runs": runs, "com_apart_cm": apart,
                      "segments_apart_rms_cm": bodies_apart,
                      "distance_ratio_mujoco_bullet": m["distance_m"] / b["distance_m"] if b["distance_m"] else None}))


if __name__ == "__main__":
    main()
