"""Which random gaits of a controller space locomote at all, and why the others do not.

For each space: N uniform random gaits (seeds 0..N-1), each run for --duration s. A gait locomotes
when its COM moves faster than --threshold cm/s after the initial contraction (from --settle s to the
end). For each trial it also records how much of the time the CPG strings' motors run at their speed
limit (the rest length changing at >= 95 % of the motor speed) and how far the motors really move the
rest lengths (their standard deviation over time, `rest_length_swing_cm`): a motor asked for more
speed or acceleration than it has follows a small triangle wave instead of the commanded motion,
and the gait vibrates. Intrinsic
frequency and target amplitude of the nodes are reported with the motion the impedance law asks
of the motor, 2 pi f B a / k (cm/s), against the motor's speed.

    python bench/spaces.py [--morphology tetraspine] [--spaces ntrt,ntrt-followable,sidewinding]
                           [--n 20] [--duration 5] [--workers 1]

Prints one JSON object (last line).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from spinefarm.robot.spaces import controller_space


def node_targets(morph, space, physical: np.ndarray) -> tuple[float, float]:
    """(intrinsic frequency Hz, target amplitude cm/s) of the CPG nodes of a gait."""
    net = space.network(physical)
    return float(abs(net.omega_rad_s[0]) / (2 * math.pi)), float(abs(net.amplitude_cm_s[0]))


def one(morph_name: str, controller: str, seed: int, duration_s: float, settle_s: float) -> dict:
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, simulate

    morph = load_morphology(morph_name)
    space = controller_space(morph, controller)
    u = random_unit_params(morph, seed, controller)
    physical = space.param_space.from_unit(u)
    freq_hz, amp_cm_s = node_targets(morph, space, physical)
    cfg = TrialConfig(duration_s=duration_s, controller=controller, record_every_s=0.002)
    out = simulate(morph, u, cfg, seed)
    r = out.result
    t, path = out.com_path_time_s, out.com_path_cm
    after = t >= settle_s
    speed_after = float("nan")
    if r.ok and after.sum() >= 2:
        p0, p1 = path[after][0], path[after][-1]
        speed_after = float(np.hypot(p1[0] - p0[0], p1[2] - p0[2]) / (t[after][-1] - t[after][0]))
    arr = out.trajectory.arrays()
    nodes = space.network(physical).node_string
    rest = arr["rest_length_cm"][:, nodes]
    rate = np.abs(np.diff(rest, axis=0)) / np.diff(arr["time_s"])[:, None]
    mats = dict(morph.structure.string_materials)
    v_motor = np.array([mats[morph.structure.strings[i].tag].motor_speed_cm_s for i in nodes])
    steady = arr["time_s"][1:] >= settle_s
    pinned = float(np.mean(rate[steady] >= 0.95 * v_motor)) if steady.any() else float("nan")
    # how far the motors actually move the rest lengths: std over time, mean over CPG strings (cm)
    swing = float(np.mean(np.std(rest[arr["time_s"] >= settle_s], axis=0)))
    gains = dict(morph.control.impedance)
    s0 = morph.structure.strings[nodes[0]]
    demand = 2 * math.pi * freq_hz * gains[s0.tag].velocity_gain_n_s_per_m * amp_cm_s / mats[s0.tag].stiffness_n_per_m
    return {"seed": seed, "status": r.status.value, "speed_cm_s": r.speed_cm_s, "speed_after_settle_cm_s": speed_after,
            "cot": r.cot, "frequency_hz": freq_hz, "amplitude_cm_s": amp_cm_s, "motor_speed_cm_s": float(v_motor[0]),
            "rest_length_speed_demand_cm_s": demand, "motor_pinned_share": pinned,
            "rest_length_swing_cm": swing, "wall_time_s": r.wall_time_s}


def summarise(rows: list[dict], threshold: float) -> dict:
    ok = [r for r in rows if r["status"] == "complete"]
    moving = [r for r in ok if r["speed_after_settle_cm_s"] > threshold]
    followable = [r for r in ok if r["rest_length_speed_demand_cm_s"] <= r["motor_speed_cm_s"]
                  and r["amplitude_cm_s"] <= r["motor_speed_cm_s"]]
    still = [r for r in ok if r not in moving]
    speeds = [r["speed_after_settle_cm_s"] for r in ok]

    def share(sub, of):
        return None if not of else round(len(sub) / len(of), 3)

    return {
        "n": len(rows), "failed": len(rows) - len(ok),
        "locomote_share": share(moving, rows),
        "median_speed_after_settle_cm_s": float(np.median(speeds)) if speeds else None,
        "max_speed_after_settle_cm_s": float(np.max(speeds)) if speeds else None,
        "followable_share": share(followable, ok),
        "locomote_share_followable": share([r for r in followable if r in moving], followable),
        "locomote_share_not_followable": share([r for r in ok if r not in followable and r in moving],
                                               [r for r in ok if r not in followable]),
        "median_motor_pinned_share_moving": float(np.median([r["motor_pinned_share"] for r in moving]))
        if moving else None,
        "median_motor_pinned_share_still": float(np.median([r["motor_pinned_share"] for r in still]))
        if still else None,
        "median_rest_length_swing_cm_moving": float(np.median([r["rest_length_swing_cm"] for r in moving]))
        if moving else None,
        "median_rest_length_swing_cm_still": float(np.median([r["rest_length_swing_cm"] for r in still]))
        if still else None,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--morphology", default="tetraspine")
    ap.add_argument("--spaces", default="ntrt,ntrt-followable,sidewinding")
    ap.add_argument("--n", type=int, default=20, help="random gaits per space")
    ap.add_argument("--duration", type=float, default=5.0, help="simulated seconds per trial")
    ap.add_argument("--settle", type=float, default=1.0, help="seconds of initial contraction not counted")
    ap.add_argument("--threshold", type=float, default=1.0, help="cm/s a gait must exceed to locomote")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--trials", action="store_true", help="also print every trial")
    args = ap.parse_args()
    t0 = time.perf_counter()
    out: dict = {"morphology": args.morphology, "duration_s": args.duration, "settle_s": args.settle,
                 "threshold_cm_s": args.threshold, "spaces": {}}
    with ProcessPoolExecutor(args.workers) as pool:
        for controller in args.spaces.split(","):
            futs = [pool.submit(one, args.morphology, controller, s, args.duration, args.settle)
                    for s in range(args.n)]
            rows = [f.result() for f in futs]
            out["spaces"][controller] = summarise(rows, args.threshold)
            if args.trials:
                out["spaces"][controller]["trials"] = rows
    out["wall_time_s"] = time.perf_counter() - t0
    print(json.dumps(out, indent=1, default=float))


if __name__ == "__main__":
    main()
