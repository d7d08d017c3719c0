"""The morphology contract: what every robot, built-in or a user's spec file, must satisfy before it is
searched. `spinefarm check FILE.yaml` runs it and the test suite runs it over every built-in.

Checks: it builds (bodies, strings, parameter space, string tables); masses, inertias and start lengths
are sane; a passive settle (no CPG output) holds its shape; two runs of a short controlled trial agree.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from spinefarm.protocol.errors import SpinefarmError
from spinefarm.robot.bodies import build_bodies, build_strings, lowest_rod_surface_cm
from spinefarm.robot.engines import DEFAULT_ENGINE
from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.spaces import controller_space, param_space
from spinefarm.worker.trial.feasibility import passive_params, step_config

__all__ = ["CheckResult", "passive_params", "run_contract"]


@dataclass(frozen=True)
class CheckResult:
    name: str
    passed: bool
    detail: str


def check_builds(morph: Morphology) -> CheckResult:
    from spinefarm.worker.control.law import string_tables

    bodies = build_bodies(morph.structure)
    geom = build_strings(morph.structure, bodies)
    for controller in morph.controllers:
        space = controller_space(morph, controller)
        space.network(space.param_space.from_unit(np.full(len(space.param_space), 0.5)))
    string_tables(morph, geom.start_length_cm, {})
    return CheckResult("builds", True, f"{len(bodies)} segments, {len(geom.start_length_cm)} strings, "
                       f"controllers {', '.join(morph.controllers)}")


def check_sane_numbers(morph: Morphology) -> CheckResult:
    bodies = build_bodies(morph.structure)
    geom = build_strings(morph.structure, bodies)
    problems = []
    for b in bodies:
        i = np.asarray(b.inertia_kg_cm2)
        if not (np.isfinite(b.mass_kg) and b.mass_kg > 0):
            problems.append(f"segment {b.index} mass {b.mass_kg:g} kg")
        if not (np.all(np.isfinite(i)) and np.all(i > 0) and np.all(2 * i <= i.sum() * (1 + 1e-9))):
            problems.append(f"segment {b.index} inertia {i.tolist()} kg cm^2 (positive, each <= sum of the others)")
    bad = np.flatnonzero(~(np.isfinite(geom.start_length_cm) & (geom.start_length_cm > 0)))
    problems += [f"string {k} start length {geom.start_length_cm[k]:g} cm" for k in bad[:5]]
    same = np.flatnonzero(geom.body_a == geom.body_b)
    problems += [f"string {k} ties segment {geom.body_a[k]} to itself" for k in same[:5]]
    if problems:
        return CheckResult("sane masses, inertias and start lengths", False, "; ".join(problems[:8]))
    masses = [b.mass_kg for b in bodies]
    return CheckResult("sane masses, inertias and start lengths", True,
                       f"segments {min(masses):.4g}-{max(masses):.4g} kg, strings "
                       f"{geom.start_length_cm.min():.3g}-{geom.start_length_cm.max():.3g} cm")


def check_passive_settle(morph: Morphology, engine: str = DEFAULT_ENGINE, duration_s: float = 5.0) -> CheckResult:
    """With no CPG output the structure stays in one piece, above ground, in a steady shape, at rest."""
    from spinefarm.worker.trial.simulation import simulate

    name = "passive settle holds its shape"
    cfg = step_config(morph, engine, duration_s=duration_s, record_every_s=duration_s / 20)
    out = simulate(morph, passive_params(morph), cfg, 0)
    if not out.result.ok:
        return CheckResult(name, False, out.result.reason)
    a = out.trajectory.arrays()
    com = a["poses"][:, :, :3]
    gaps = np.linalg.norm(np.diff(com, axis=1), axis=2)
    ratio = gaps[-1] / gaps[0]
    if ratio.min() < 0.6 or ratio.max() > 1.4:
        k = int(np.argmax(np.abs(np.log(ratio))))
        return CheckResult(name, False, f"segments {k} and {k + 1} went from {gaps[0, k]:.3g} cm to "
                           f"{gaps[-1, k]:.3g} cm apart (allowed 0.6x-1.4x): the structure falls apart")
    late = gaps[-1] / gaps[-9]
    if np.abs(late - 1.0).max() >= 0.06:
        return CheckResult(name, False, f"still changing shape by {np.abs(late - 1).max():.1%} in the last "
                           f"{a['time_s'][-1] - a['time_s'][-9]:.2g} s (allowed < 6 %)")
    bodies = build_bodies(morph.structure)
    drop = min(b.com_cm[1] for b in bodies) - lowest_rod_surface_cm(morph.structure)
    if com[-1, :, 1].min() <= 0.5 + 0.3 * drop:
        return CheckResult(name, False, f"a segment sank to {com[-1, :, 1].min():.3g} cm (COM height)")
    masses = np.array([b.mass_kg for b in bodies])
    robot = (com * masses[None, :, None]).sum(axis=1) / masses.sum()
    speed = np.linalg.norm(robot[-1] - robot[-5]) / (a["time_s"][-1] - a["time_s"][-5])
    if speed >= 1.5:
        return CheckResult(name, False, f"still moving at {speed:.3g} cm/s after {duration_s:g} s (allowed 1.5)")
    return CheckResult(name, True, f"gaps {ratio.min():.3g}-{ratio.max():.3g}x of the start, at rest "
                       f"({speed:.2g} cm/s)")


def check_deterministic(morph: Morphology, engine: str = DEFAULT_ENGINE) -> CheckResult:
    from spinefarm.worker.trial.simulation import simulate

    name = "two runs agree"
    u = np.random.default_rng(7).random(len(param_space(morph)))
    cfg = step_config(morph, engine, duration_s=0.5, record_every_s=0.1)
    a, b = simulate(morph, u, cfg, 3), simulate(morph, u, cfg, 3)
    if not a.result.ok:
        return CheckResult(name, False, f"a short controlled trial failed: {a.result.reason}")
    same = np.array_equal(a.trajectory.arrays()["poses"], b.trajectory.arrays()["poses"])
    if not same or a.result.work_j != b.result.work_j:
        return CheckResult(name, False, "two runs with the same parameters and seed differ")
    if not a.result.work_j > 0.0:
        return CheckResult(name, False, "the controller did no work: no string is actuated")
    return CheckResult(name, True, f"identical poses; work {a.result.work_j:.3g} J in 0.5 s")


def run_contract(morph: Morphology, engine: str = DEFAULT_ENGINE,
                 progress: Callable[[int, int], None] | None = None) -> list[CheckResult]:
    """Every check, in order; a check that raises fails with the error (later ones still run if the
    structure built). `progress(done, total)` before the first and after each."""
    out: list[CheckResult] = []
    checks = (check_builds, check_sane_numbers, check_passive_settle, check_deterministic)
    if progress:
        progress(0, len(checks))
    for check in checks:
        try:
            result = check(morph) if check in (check_builds, check_sane_numbers) else check(morph, engine)
        except SpinefarmError as exc:
            result = CheckResult(check.__name__.removeprefix("check_").replace("_", " "), False, str(exc))
        out.append(result)
        if progress:
            progress(len(out), len(checks))
        if check is check_builds and not result.passed:
            break
    return out
