"""Can a fit find constants it knows? Recordings made with our own model under changed constants, fitted from
the model's own values: each constant recovered within TOLERANCE, or said why not (bench/fit.py --identify).

Two reasons a recording cannot tell a constant: it is seen only in a product with another (the engines combine
the ground's and a rod's friction as their product, PRODUCTS), or the loss hardly moves with it (a change of
PROBE around the fitted value moves the loss by less than FLAT of itself), or it is one of a group whose common
scale the motion does not show (SCALES).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any

from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.profile import constant, current_value
from spinefarm.robot.spaces import param_space
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.fit.fitting import fit_constants, with_values
from spinefarm.worker.fit.loss import Prepared, fit_loss, prepare
from spinefarm.worker.fit.readers import from_trajectory
from spinefarm.worker.fit.recording import Recording
from spinefarm.worker.fit.search import Bound

TOLERANCE = 0.05
PRODUCTS = (("ground_friction", "rod_friction"),)  # Bullet multiplies the two; MuJoCo is mapped to the product
# scaled together they leave every acceleration as it was (rest-length drive, load-proportional contacts)
SCALES = ("rod_density_kg_per_cm3", "string_stiffness_n_per_m", "string_damping_n_s_per_m")
PROBE = 0.05
FLAT = 0.02


def record(morph: Morphology, cfg: TrialConfig, seed: int, duration_s: float) -> Recording:
    """A trial of a seeded random gait under cfg, recorded at every step, as a recording."""
    import numpy as np

    from spinefarm.worker.trial.simulation import random_unit_params, simulate

    run = dataclasses.replace(cfg, duration_s=duration_s, record_every_s=cfg.step_s)
    unit = random_unit_params(morph, seed)
    out = simulate(morph, unit, run, seed)
    space = param_space(morph, None)
    return from_trajectory(out.trajectory.arrays(), run.to_dict(),
                           space.to_named(space.from_unit(np.asarray(unit))), f"seed {seed}", morph.name)


def identify(morph: Morphology, engine: str, true: Mapping[str, float], seeds: Sequence[int] = (3, 5),
             duration_s: float = 2.0, window_s: float = 0.2, restarts: int = 3, evaluations: int = 200,
             span: float = 2.0) -> dict[str, Any]:
    """Record under `true`, fit the same names from the model's values within [value / span, value * span] (and
    their plausible ranges) and
    judge each: {"constants": {name: {true, fitted, rel_error, identifiable, why}}, ...}."""
    base = TrialConfig(engine=engine)
    recordings = [prepare(f"seed {s}", record(morph, with_values(base, true), s, duration_s), window_s, window_s)
                  for s in seeds]
    start = {n: current_value(morph, n, engine, {}) for n in true}
    bounds = [Bound(n, max(v / span, constant(n)[0].low), min(v * span, constant(n)[0].high))
              for n, v in start.items()]
    result = fit_constants(morph, base, recordings, [], bounds, restarts, evaluations)
    fitted = {n: c["fitted"] for n, c in result["constants"].items()}
    judged = {n: {"true": true[n], "fitted": fitted[n], "rel_error": abs(fitted[n] - true[n]) / abs(true[n]),
                  "identifiable": abs(fitted[n] - true[n]) <= TOLERANCE * abs(true[n])} for n in true}
    _why(judged, morph, base, fitted, recordings, result["loss"]["after"])
    return {"robot": morph.name, "engine": engine, "seeds": list(seeds), "duration_s": duration_s,
            "window_s": window_s, "tolerance": TOLERANCE, "constants": judged,
            "window_error_cm": result["window_error_cm"], "loss": result["loss"], "restarts": result["restarts"],
            "evaluations": result["evaluations"]}


def _why(judged: dict[str, dict], morph: Morphology, cfg: TrialConfig, fitted: dict[str, float],
         recordings: list[Prepared], loss: float) -> None:
    for a, b in PRODUCTS:
        if a in judged and b in judged:
            true = judged[a]["true"] * judged[b]["true"]
            got = fitted[a] * fitted[b]
            if abs(got - true) <= TOLERANCE * true:
                for n in (a, b):
                    judged[n]["why"] = (f"only the product {a} x {b} is seen (the engines combine the two "
                                        f"frictions as their product): fitted {got:.4g}, true {true:.4g}")
    ratios = {n: fitted[n] / judged[n]["true"] for n in SCALES if n in judged}
    if len(ratios) > 1 and max(ratios.values()) <= (1 + TOLERANCE) * min(ratios.values()) \
            and not all(judged[n]["identifiable"] for n in ratios):
        for n in ratios:
            judged[n]["why"] = (f"only the ratios of {', '.join(ratios)} to each other are seen: all came out "
                                f"{min(ratios.values()):.3g}-{max(ratios.values()):.3g}x the true ones (a common "
                                "scale leaves the motion as it was; the strings' tensions tell it)")
    for n, j in judged.items():
        if j["identifiable"] or "why" in j:
            continue
        moved = [fit_loss(morph, with_values(cfg, {**fitted, n: fitted[n] * f}), recordings)
                 for f in (1 - PROBE, 1 + PROBE)]
        change = max(abs(m - loss) for m in moved) / loss if loss > 0 else math.inf
        j["why"] = (f"a {100 * PROBE:g} % change moves the loss by {100 * change:.2g} % "
                    + ("(flat: the recordings barely see it)" if change < FLAT else
                       "(the fit stopped short or another constant makes up for it)"))
