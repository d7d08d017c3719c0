"""One segment alone on the ground, pushed: does each engine's ground contact give the same response?

A spine's first segment is dropped on flat ground from its build pose, left to settle, then pushed
by a constant horizontal force at its COM (a multiple of the Coulomb limit mu * m * g, mu the friction
product of rod and ground) along x, z or the diagonal between them (where a friction pyramid and a
friction box differ most from Coulomb's circle), or turned by a constant torque about the vertical; each engine
at its default step and settings. Prints one JSON object: per engine and push, how far the segment slid
(cm), how far it turned (rad) and its height change (cm). Below the limit a rigid Coulomb contact does
not slide at all; above it the segment accelerates at (F - mu m g) / m.

    python bench/contact_probe.py ribbed
    python bench/contact_probe.py octahedral-complex --push 1.2 --seconds 0.5
    python bench/contact_probe.py ribbed --mujoco-options '{"contact_geometry": "cylinders"}'
"""

from __future__ import annotations

import argparse
import json

import numpy as np


def _contacts(world) -> int:
    """Ground contacts of the one segment (Bullet: the points of its manifold; MuJoCo: its contacts)."""
    if world.name == "bullet":
        import pybullet as pb

        return len(pb.getContactPoints(physicsClientId=world.worlds[0].client))
    return world.contact_count()


def probe(spine: str, engine: str, factors: list[float], settle_s: float, push_s: float, options: dict) -> dict:
    from spinefarm.robot.bodies import quaternion_matrix
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.worker.engines.base import GRAVITY_CM_S2, engine_class
    from spinefarm.worker.trial.setup import TrialSetup
    from spinefarm.worker.trial.simulation import TrialConfig

    morph = load_morphology(spine)
    setup = TrialSetup(morph, TrialConfig(engine=engine, engine_options=options), None)
    body = setup.bodies[0]
    mu = body.friction * setup.terrain.friction
    limit = mu * body.mass_kg * GRAVITY_CM_S2
    n_settle, n_push = round(settle_s / setup.dt), round(push_s / setup.dt)
    out = {}
    diagonal = np.array([1.0, 0.0, 1.0]) / np.sqrt(2.0)  # between the friction directions of both engines
    pushes = [(f"{axis}x{f:g}", direction * f * limit, np.zeros(3)) for f in factors
              for axis, direction in (("x", np.eye(3)[0]), ("z", np.eye(3)[2]), ("xz", diagonal))]
    # a torque about the vertical: the force limit times the segment's half width as a lever
    half_width = float(np.ptp([r.centre_cm[0] for r in body.rods])) / 2 or 1.0
    pushes += [(f"yaw_x{f:g}", np.zeros(3), np.array([0.0, f * limit * half_width, 0.0])) for f in factors]
    for name, force, torque in pushes:
        with engine_class(engine)([body], setup.terrain, setup.dt, setup.settings) as world:
            zero = np.zeros((1, 1, 3))
            for _ in range(n_settle):
                world.read_poses()
                world.apply_wrenches(zero, zero)
                world.step()
            start = world.read_poses()[0, 0].copy()
            n_contacts = _contacts(world)
            for _ in range(n_push):
                world.read_poses()
                world.apply_wrenches(force[None, None], torque[None, None])
                world.step()
            end = world.read_poses()[0, 0].copy()
        r0, r1 = quaternion_matrix(start[3:]), quaternion_matrix(end[3:])
        turn = float(np.arccos(np.clip((np.trace(r1 @ r0.T) - 1) / 2, -1.0, 1.0)))
        out[name] = {"slid_cm": float(np.hypot(*(end[[0, 2]] - start[[0, 2]]))), "turned_rad": turn,
                     "height_change_cm": float(end[1] - start[1]), "rest_height_cm": float(start[1]),
                     "contacts_at_rest": n_contacts}
    return {"coulomb_limit": limit, "mu": mu, "mass_kg": body.mass_kg, "dt_s": setup.dt, "pushes": out}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("spine")
    ap.add_argument("--push", default="0.5,0.9,1.2", help="forces as multiples of the Coulomb limit")
    ap.add_argument("--settle", type=float, default=0.5, help="seconds to settle before the push")
    ap.add_argument("--seconds", type=float, default=0.5, help="seconds of pushing")
    ap.add_argument("--mujoco-options", default="{}")
    ap.add_argument("--bullet-options", default="{}")
    args = ap.parse_args()
    factors = [float(v) for v in args.push.split(",")]
    print(json.dumps({"benchmark": "contact_probe", "spine": args.spine, "settle_s": args.settle,
                      "push_s": args.seconds,
                      "engines": {e: probe(args.spine, e, factors, args.settle, args.seconds,
                                           json.loads(getattr(args, f"{e}_options")))
                                  for e in ("bullet", "mujoco")}}))


if __name__ == "__main__":
    main()
