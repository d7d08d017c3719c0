"""What limits a gait's speed: the gait re-run with one thing changed at a time (a measurement, not a model change).

Takes a --params gait file (examples/gaits/<morphology>.json) and runs it at the morphology's trial
length as shipped, then with: ground friction x0.5 and x2, motor speed and acceleration x2, maximum
string tension x2, impedance velocity gain B x0.5 (a CPG setpoint then asks for half the tension
swing) and a trial twice as long. Prints, per variant, speed, COT and the ratio of speed to the
shipped model's, as one JSON object (last line).

    python bench/ceiling.py examples/gaits/tetraspine.json [--duration S] [--workers 2]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def run(variant: str, gait_path: str, duration_s: float | None) -> dict:
    import dataclasses

    from spinefarm.cli.sim_commands import load_params_file
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.robot.morphology.variants import with_gains, with_strings
    from spinefarm.worker.trial.simulation import TrialConfig, simulate

    params, controller = load_params_file(Path(gait_path))
    morph = load_morphology(json.loads(Path(gait_path).read_text())["morphology"])
    length = duration_s or morph.duration_s
    cfg = TrialConfig(duration_s=length, controller=controller)
    mats = dict(morph.structure.string_materials)
    if variant == "friction_x0.5":
        cfg = dataclasses.replace(cfg, ground_friction=morph.ground_friction * 0.5)
    elif variant == "friction_x2":
        cfg = dataclasses.replace(cfg, ground_friction=morph.ground_friction * 2.0)
    elif variant == "motor_x2":
        m = next(iter(mats.values()))
        morph = with_strings(morph, motor_speed_cm_s=2 * m.motor_speed_cm_s, motor_accel_cm_s2=2 * m.motor_accel_cm_s2)
    elif variant == "max_tension_x2":
        morph = with_strings(morph, max_tension_n=2 * next(iter(mats.values())).max_tension_n)
    elif variant == "velocity_gain_x0.5":
        morph = with_gains(morph, velocity_gain_n_s_per_m=0.5 * dict(morph.control.impedance)[
            next(iter(dict(morph.control.impedance)))].velocity_gain_n_s_per_m)
    elif variant == "length_x2":
        cfg = dataclasses.replace(cfg, duration_s=2 * length)
    elif variant != "as_shipped":
        raise ValueError(variant)
    r = simulate(morph, params, cfg).result
    return {"variant": variant, "status": r.status.value, "speed_cm_s": r.speed_cm_s, "cot": r.cot,
            "distance_m": r.distance_m, "duration_s": cfg.duration_s, "wall_time_s": r.wall_time_s}


VARIANTS = ("as_shipped", "friction_x0.5", "friction_x2", "motor_x2", "max_tension_x2", "velocity_gain_x0.5",
            "length_x2")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("gait", help="a --params gait file with a morphology key")
    ap.add_argument("--duration", type=float, default=None, help="trial length (default the morphology's)")
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(pool.map(run, args.variants.split(","), [args.gait] * 99, [args.duration] * 99))
    base = next((r["speed_cm_s"] for r in rows if r["variant"] == "as_shipped"), None)
    for r in rows:
        r["speed_ratio"] = r["speed_cm_s"] / base if base else None
    print(json.dumps({"gait": args.gait, "variants": rows, "wall_time_s": time.perf_counter() - t0}))


if __name__ == "__main__":
    main()
