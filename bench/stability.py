"""Hard cases for explicit string integration: the largest stable step measured against the estimate.

For each case the stable-step estimate (worker.sim.stability, from the string network linearised at
the start pose) is printed beside the largest step at which a 1 s trial stays sane, found by
geometric bisection (a run counts as stable when it completes without a divergence verdict).
The last line is one JSON object.

    python bench/stability.py [--duration 1.0] [--iterations 8] [--case NAME ...]
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Callable

import numpy as np

from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.morphology.variants import with_density_factor, with_gains, with_strings
from spinefarm.worker.sim.stability import estimate_stable_step
from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, simulate


def _edge_params(morph: Morphology, seed: int) -> np.ndarray:
    u = random_unit_params(morph, seed)
    u[0] = u[1] = 1.0  # frequency and amplitude at their upper bounds
    return u


BASE = "tetraspine-ntrt"
CASES: dict[str, tuple[str, Callable[[], Morphology], Callable[[Morphology, int], np.ndarray]]] = {
    "reference": ("NTRT's 3-segment Tetraspine as published", lambda: load_morphology(BASE), random_unit_params),
    "hardware-stiffness": ("strings 600x stiffer (600,000 N/m), no in-line springs",
                           lambda: with_strings(load_morphology(BASE), stiffness_n_per_m=600_000.0),
                           random_unit_params),
    "light-long-levers": ("segments 50x lighter (49 g), same 38 cm lever arms: large damping rates",
                          lambda: with_density_factor(load_morphology(BASE), 0.02), random_unit_params),
    "cpg-edge": ("CPG frequency and amplitude at the upper bounds (90 Hz, 90 cm/s)",
                 lambda: load_morphology(BASE), _edge_params),
    "tension-saturation": ("motor tension limit 5 N: strings held at the limit all trial",
                           lambda: with_strings(load_morphology(BASE), max_tension_n=5.0), random_unit_params),
    "large-pretension": ("60 N pretension in every string (rest length 6 cm short)",
                         lambda: with_strings(load_morphology(BASE), pretension_n=60.0), random_unit_params),
    "slack-taut-chatter": ("control length = start length, no tension offset, amplitude at its bound: "
                           "strings cycle slack and taut",
                           lambda: with_gains(load_morphology(BASE), control_length_cm=None), _edge_params),
    "hardware-tetraspine": ("3-segment hardware prototype: 0.73 kg segments, 600,000 N/m",
                            lambda: load_morphology("tetraspine-hardware"), random_unit_params),
}


def stable(morph: Morphology, params: np.ndarray, dt: float, duration: float, seed: int) -> tuple[bool, str]:
    r = simulate(morph, params, TrialConfig(duration_s=duration, dt_s=dt, refuse_unstable_dt=False), seed).result
    return r.status == "complete", r.reason


def largest_stable_step(morph, params, duration, seed, iterations, lo=1e-5, hi=2e-2) -> tuple[float, str]:
    ok, _ = stable(morph, params, hi, duration, seed)
    if ok:
        return hi, ""
    last_reason = ""
    for _ in range(iterations):
        mid = math.sqrt(lo * hi)
        ok, reason = stable(morph, params, mid, duration, seed)
        if ok:
            lo = mid
        else:
            hi, last_reason = mid, reason
    return lo, last_reason


def main() -> None:
    from spinefarm.cli import checks  # an argparse type: seeds are whole numbers >= 0

    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--duration", type=float, default=1.0)
    ap.add_argument("--iterations", type=int, default=8)
    ap.add_argument("--seed", type=checks.seed, default=1)
    ap.add_argument("--case", action="append", choices=sorted(CASES))
    args = ap.parse_args()
    rows = []
    for name in args.case or list(CASES):
        doc, make, params_of = CASES[name]
        morph = make()
        est = estimate_stable_step(morph)
        measured, reason = largest_stable_step(morph, params_of(morph, args.seed), args.duration, args.seed,
                                               args.iterations)
        row = {"case": name, "description": doc, **est.to_dict(), "measured_largest_stable_dt_s": measured,
               "measured_over_estimate": measured / est.dt_limit_s, "first_unstable_reason": reason}
        rows.append(row)
        print(f"{name:20s} estimate {est.dt_limit_s * 1e3:8.3f} ms  measured {measured * 1e3:8.3f} ms  "
              f"ratio {measured / est.dt_limit_s:5.2f}  ({reason})", flush=True)
    print(json.dumps({"benchmark": "stability", "duration_s": args.duration, "cases": rows}))


if __name__ == "__main__":
    main()
