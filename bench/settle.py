"""How far a robot drifts with its CPG at rest, with and without a settle phase, on both engines.

A still robot's "distance" is its settling motion (it contracts to its control lengths and comes to rest on
the ground): what a settle phase (TrialConfig.settle_s) keeps out of a short trial's score. The sidewinding
Tetraspine with both amplitudes zero (the CPG's output is zero: the impedance reflex alone holds the
posture), each engine at its default step. Prints one JSON object: per engine, the distance in cm of each
(settle, scored seconds) row.

    python bench/settle.py [--morphology tetraspine]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from spinefarm.robot.spaces import controller_space

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

# (settle s, scored s): the first 0.5 s and 1 s unsettled, then 1 s after a 0.5 s and a 1 s settle
ROWS = ((0.0, 0.5), (0.0, 1.0), (0.5, 1.0), (1.0, 1.0))


def at_rest(morphology: str) -> dict[str, float]:
    """A sidewinding gait whose amplitudes are zero: the CPG at rest."""
    from spinefarm.robot.morphology.registry import load_morphology

    names = controller_space(load_morphology(morphology), "sidewinding").param_space.names
    values = {"frequency_offset_hz": 0.5, "frequency_gain_hz": 0.5, "amplitude_offset_cm_s": 0.0,
              "amplitude_gain_cm_s": 0.0, "descending_command": 1.0}
    return {n: values.get(n, 0.0) for n in names}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--morphology", default="tetraspine")
    args = ap.parse_args()
    from spinefarm.robot.trial_config import TrialConfig
    from spinefarm.worker.trial.simulation import simulate

    params = at_rest(args.morphology)
    t0 = time.time()
    out: dict[str, list[dict]] = {}
    for engine in ("bullet", "mujoco"):
        out[engine] = []
        for settle_s, scored_s in ROWS:
            cfg = TrialConfig(duration_s=scored_s, settle_s=settle_s, engine=engine, controller="sidewinding")
            r = simulate(args.morphology, params, cfg, 0).result
            out[engine].append({"settle_s": settle_s, "scored_s": scored_s, "status": r.status.value,
                                "distance_cm": round(100 * r.distance_m, 4)})
    print(json.dumps({"benchmark": "settle", "morphology": args.morphology, "rows": out,
                      "wall_s": round(time.time() - t0, 1)}))


if __name__ == "__main__":
    main()
