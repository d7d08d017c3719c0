"""Our cost of transport against the paper's definition (section III-D), term by term, for each shipped gait.

    python bench/cot_terms.py [--duration 10] [--gaits tetraspine,ribbed,...]

COT = W / (m g d). The paper: W is "the sum of the work used to shorten the strings: tension times distance
shortened at each timestep", relaxation passive; m the robot's mass; d the distance travelled. Each trial is
recorded at every step; the JSON gives, per gait, W as we count it (tension before each step's shortening, every
string), W with the tension after the step (split by the strings the CPG drives, impedance-controlled, and the
rest), m, the robot's centre-of-mass distance (ours) and the scored segment's (NTRT's), and the COT each choice
gives.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

GAITS = Path(__file__).resolve().parent.parent / "examples" / "gaits"
G_M_S2 = 9.81


def terms(name: str, duration_s: float) -> dict:
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.robot.trial_config import TrialConfig
    from spinefarm.worker.trial.simulation import simulate

    spec = json.loads((GAITS / f"{name}.json").read_text())
    morph = load_morphology(spec["morphology"])
    cfg = TrialConfig(duration_s=duration_s, controller=spec.get("controller"))
    cfg = TrialConfig.from_dict({**cfg.to_dict(), "record_every_s": cfg.step_s})
    out = simulate(morph, spec["params"], cfg, seed=0)
    r, a = out.result, out.trajectory.arrays()
    strings = morph.structure.strings
    cpg = np.array([morph.control.gains(s.tag) is not None for s in strings])
    rest, tension = a["rest_length_cm"], a["tension_n"]
    short = np.maximum(0.0, rest[:-1] - rest[1:])
    per_string_j = (tension[1:] * short).sum(axis=0) * 0.01  # N cm -> J
    after_j = float(per_string_j.sum())
    m = r.mass_kg
    d_com, d_seg = r.distance_m, r.ntrt_distance_cm / 100.0
    w_cpg = float(per_string_j[cpg].sum())

    def cot(w: float, d: float) -> float:
        return w / (m * G_M_S2 * d) if d > 0 else float("inf")

    return {"gait": name, "duration_s": duration_s, "mass_kg": m, "work_j": r.work_j,
            "work_tension_after_step_j": after_j,
            "work_cpg_strings_j": w_cpg, "work_other_strings_j": float(per_string_j[~cpg].sum()),
            "n_strings": len(strings), "n_cpg_strings": int(cpg.sum()),
            "distance_com_m": d_com, "distance_scored_segment_m": d_seg, "speed_cm_s": r.speed_cm_s,
            "cot": r.cot, "cot_scored_segment": cot(r.work_j, d_seg), "cot_cpg_strings_only": cot(w_cpg, d_com),
            "cot_tension_after_step": cot(after_j, d_com)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=10.0, help="simulated seconds per gait")
    ap.add_argument("--gaits", default="tetraspine,tetrahedral-complex,octahedral-complex,ribbed")
    args = ap.parse_args()
    print(json.dumps([terms(g, args.duration) for g in args.gaits.split(",")], indent=1))


if __name__ == "__main__":
    main()
