"""Speed against error: the same seeded trials over a sweep of numerical settings and scenes.

Each setting is a set of TrialConfig overrides. Every parameter set is run once per setting and
compared with a converged reference of the same parameter set: the physics step is halved from 0.25 ms
until the final distance changes by less than 0.1 % (or the floor is reached: 0.25 ms with --quick,
else 0.03125 ms; the report says which). The model itself does not change with the step (motor limits
and control rates are in physical units). Chaotic gaits are caught by a "chaos floor": the
difference between two references whose start poses differ by 1e-6 cm; errors below it are noise.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from statistics import median
from typing import Any

import numpy as np

from spinefarm.robot.engines import engine_spec
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.worker.tools.pool import Progress, process_pool
from spinefarm.worker.trial import scoring
from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, simulate


def baseline_label(engine: str = "bullet") -> str:
    return f"dt {engine_spec(engine).default_dt_s * 1e3:g} ms (default)"


@dataclass(frozen=True)
class Setting:
    label: str
    group: str  # step | solver | cpg | contacts | scene
    overrides: dict[str, Any] = field(default_factory=dict)

    @property
    def numerical(self) -> bool:
        """Settings that should converge to the same motion (scenes change the task instead)."""
        return self.group != "scene"


def sweep(quick: bool, engine: str = "bullet") -> list[Setting]:
    steps = (2e-3, 1e-3, 5e-4) if quick else (4e-3, 2e-3, 1e-3, 5e-4, 2.5e-4)
    if engine == "mujoco" and not quick:
        steps = (8e-3, 4e-3, 3e-3, 2e-3, 1e-3, 5e-4, 2.5e-4)
    default = engine_spec(engine).default_dt_s
    if default not in steps:
        steps = tuple(sorted((*steps, default), reverse=True))
    out = [Setting(baseline_label(engine) if dt == default else f"dt {dt * 1e3:g} ms", "step", {"dt_s": dt})
           for dt in steps]
    if engine == "mujoco":
        return out + _mujoco_settings(quick) + _scenes()
    iterations = (50,) if quick else (5, 20, 50)
    out += [Setting(f"solver {n} iterations", "solver", {"engine_options": {"solver_iterations": n}})
            for n in iterations]
    out += [Setting("CPG RK4 sub-step 0.125 ms", "cpg", {"cpg_max_step_s": 1.25e-4})]
    out += [Setting("collisions: neighbours only", "contacts", {"scene": {"collision_filter": "neighbours"}}),
            Setting("friction anchors off", "contacts", {"engine_options": {"friction_anchor": False}})]
    if not quick:
        out += [Setting("solver 20 iterations, dt 0.5 ms", "solver",
                        {"dt_s": 5e-4, "engine_options": {"solver_iterations": 20}})]
    return out + _scenes()


def _mujoco_settings(quick: bool) -> list[Setting]:
    out = [Setting("contacts: capsules (no rod-end proxies)", "contacts",
                   {"engine_options": {"contact_geometry": "capsules"}}),
           Setting("contacts: segment-segment off", "contacts", {"engine_options": {"segment_contacts": "off"}}),
           Setting("contacts: solref 0.02 s (MuJoCo's default)", "contacts",
                   {"engine_options": {"solref_time_s": 0.02}}),
           Setting("CPG RK4 sub-step 0.125 ms", "cpg", {"cpg_max_step_s": 1.25e-4})]
    if not quick:
        out += [Setting("solver: CG", "solver", {"engine_options": {"solver": "cg"}}),
                Setting("integrator: Euler", "solver", {"engine_options": {"integrator": "euler"}}),
                Setting("dt 2 ms, segment-segment off", "contacts",
                        {"dt_s": 2e-3, "engine_options": {"segment_contacts": "off"}})]
    return out


def _scenes() -> list[Setting]:
    return [Setting("scene: rough 2 cm / 40 cm", "scene", {"scene": {"kind": "rough", "rough_amplitude_cm": 2.0}}),
            Setting("scene: obstacles 3 cm every 60 cm", "scene", {"scene": {"kind": "obstacles"}}),
            Setting("scene: slope 5 deg", "scene", {"scene": {"kind": "slope", "slope_deg": 5.0}})]


@dataclass(frozen=True)
class ParamSet:
    name: str
    unit: tuple[float, ...]
    seed: int


def _config(base: dict[str, Any], overrides: dict[str, Any]) -> TrialConfig:
    """A setting over the base; a setting that names a step runs at that step (a base's automatic step, for a
    robot whose default one is unstable, is for the others)."""
    merged = {**base, **overrides}
    if "dt_s" in overrides:
        merged["auto_dt"] = False
    if "scene" in base or "scene" in overrides:
        merged["scene"] = {**base.get("scene", {}), **overrides.get("scene", {})}
    if "engine_options" in base or "engine_options" in overrides:
        merged["engine_options"] = {**base.get("engine_options", {}), **overrides.get("engine_options", {})}
    return TrialConfig.from_dict(merged)


def _run(args: tuple) -> dict[str, Any]:
    morph_src, controller, ps, cfg_dict = args
    morph = load_morphology(morph_src)
    cfg = TrialConfig.from_dict(cfg_dict)
    t0 = time.perf_counter()
    try:
        out = simulate(morph, np.array(ps.unit), cfg, ps.seed, controller=controller)
    except Exception as exc:  # a refused step is a result of the sweep, not a crash of it
        return {"status": "refused", "reason": str(exc), "wall_s_per_sim_s": math.nan}
    r = out.result
    return {"status": str(r.status), "reason": r.reason, "distance_m": r.distance_m, "cot": r.cot,
            "wall_s_per_sim_s": (time.perf_counter() - t0) / max(r.sim_time_s, 1e-9),
            "path": out.com_path_cm.tolist(), "path_t": out.com_path_time_s.tolist(), "dt_s": r.extras["dt_s"]}


def _reference(args: tuple) -> dict[str, Any]:
    """Halve the step until the distance converges; also one jittered twin for the chaos floor."""
    morph_src, controller, ps, base, start_dt, floor_dt, tol = args
    dt, prev, history = start_dt, None, []
    while True:
        row = _run((morph_src, controller, ps, _config(base, {"dt_s": dt}).to_dict()))
        history.append({"dt_s": dt, "distance_m": row.get("distance_m")})
        if prev is not None and row["status"] == "complete" and prev["status"] == "complete":
            change = abs(row["distance_m"] - prev["distance_m"]) / max(abs(row["distance_m"]), 1e-9)
            if change < tol or dt / 2 < floor_dt:
                break
        elif dt / 2 < floor_dt:
            break
        prev, dt = row, dt / 2
    converged = len(history) > 1 and prev is not None and abs(
        row["distance_m"] - prev["distance_m"]) / max(abs(row["distance_m"]), 1e-9) < tol
    twin = _run((morph_src, controller, ParamSet(ps.name, ps.unit, ps.seed + 10_000),
                 _config(base, {"dt_s": dt, "pose_jitter_cm": 1e-6}).to_dict()))
    return {**row, "converged": converged, "history": history, "twin_distance_m": twin.get("distance_m")}


DISTANCE_FLOOR_M = 0.01  # errors of gaits that barely move are taken relative to 1 cm


def rel(a: float | None, b: float | None, floor: float = 1e-9) -> float:
    if a is None or b is None or not (math.isfinite(a) and math.isfinite(b)):
        return math.inf
    return abs(a - b) / max(abs(b), floor)


def abs_cm(a: float | None, b: float | None) -> float:
    if a is None or b is None or not (math.isfinite(a) and math.isfinite(b)):
        return math.inf
    return abs(a - b) * 100.0


def pareto(rows: list[dict[str, Any]]) -> list[str]:
    """Labels of settings no other setting beats in both wall time and median distance error."""
    pts = [r for r in rows if r["numerical"] and math.isfinite(r["wall_s_per_sim_s"])
           and math.isfinite(r["median_distance_error"])]
    front = []
    for r in sorted(pts, key=lambda r: (r["wall_s_per_sim_s"], r["median_distance_error"])):
        if not front or r["median_distance_error"] < front[-1]["median_distance_error"]:
            front.append(r)
    return [r["label"] for r in front]


def run_accuracy(morphology: str, *, quick: bool, seeds: int, duration_s: float | None, jobs: int,
                 best: ParamSet | list[ParamSet] | None = None, controller: str | None = None,
                 base: dict[str, Any] | None = None,
                 progress: Callable[[str], None] = lambda s: None, counted: Progress | None = None
                 ) -> dict[str, Any]:
    morph = load_morphology(morphology)
    morph_src = morphology if isinstance(morphology, str) else morph.to_dict()
    duration = duration_s or (5.0 if quick else morph.duration_s)
    base = {"duration_s": duration, **(base or {})}
    sets = [ParamSet(f"random seed {s}", tuple(random_unit_params(morph, s, controller)), s)
            for s in range(1, seeds + 1)]
    if best is not None:
        sets.extend(best if isinstance(best, list) else [best])
    settings = sweep(quick, base.get("engine", "bullet"))
    refs, runs = _simulate_all(morph_src, controller, sets, settings, base, quick, jobs, progress, counted)
    table = [_table_row(s, runs[i * len(sets):(i + 1) * len(sets)], refs) for i, s in enumerate(settings)]
    chaos = [rel(ref.get("twin_distance_m"), ref.get("distance_m"), DISTANCE_FLOOR_M) for ref in refs]
    floor = median(chaos)
    front = pareto(table)
    rec, why = _recommend(table, front, floor)
    baseline = next(r for r in table if r["label"] == baseline_label(base.get("engine", "bullet")))
    return {
        "morphology": morph.name, "engine": base.get("engine", "bullet"), "duration_s": duration, "quick": quick,
        "param_sets": [ps.name for ps in sets],
        "reference": [{"param_set": ps.name, "dt_s": ref.get("dt_s"), "converged": ref["converged"],
                       "distance_m": ref.get("distance_m"), "status": ref["status"],
                       "wall_s_per_sim_s": ref["wall_s_per_sim_s"], "history": ref["history"]}
                      for ps, ref in zip(sets, refs, strict=True)],
        "chaos_floor": floor, "chaos_differences": chaos,
        "table": table, "pareto_front": front, "recommended": rec["label"], "recommendation_reason": why,
        "default_distance_error": baseline["median_distance_error"],
        "default_wall_s_per_sim_s": baseline["wall_s_per_sim_s"],
    }


def _simulate_all(morph_src: Any, controller: str | None, sets: list[ParamSet], settings: list[Setting],
                  base: dict[str, Any], quick: bool, jobs: int, progress: Callable[[str], None],
                  counted: Progress | None = None) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """(a converged reference per parameter set, a run per setting and parameter set, setting-major);
    `counted(done, total)` after each of them."""
    start_dt, floor_dt, tol = (2.5e-4, 2.5e-4, 1e-3) if quick else (2.5e-4, 3.125e-5, 1e-3)
    ref_jobs = [(morph_src, controller, ps, base, start_dt, floor_dt, tol) for ps in sets]
    run_jobs = [(morph_src, controller, ps, _config(base, s.overrides).to_dict()) for s in settings for ps in sets]
    total, done = len(ref_jobs) + len(run_jobs), [0]
    if counted:
        counted(0, total)

    def one_more(_result: Any) -> None:  # in the pool's result thread
        done[0] += 1
        if counted:
            counted(done[0], total)

    with process_pool(max(1, jobs)) as pool:
        refs_f = [pool.apply_async(_reference, (j,), callback=one_more) for j in ref_jobs]
        runs_f = [pool.apply_async(_run, (j,), callback=one_more) for j in run_jobs]
        refs = [f.get() for f in refs_f]
        progress(f"references done for {len(sets)} parameter sets")
        runs = [f.get() for f in runs_f]
    return refs, runs


def _table_row(s: Setting, mine: list[dict[str, Any]], refs: list[dict[str, Any]]) -> dict[str, Any]:
    """One setting's errors against the references, over its runs `mine` (one per parameter set)."""
    pairs = list(zip(mine, refs, strict=True))
    d_err = [rel(r.get("distance_m"), ref.get("distance_m"), DISTANCE_FLOOR_M) for r, ref in pairs]
    d_cm = [abs_cm(r.get("distance_m"), ref.get("distance_m")) for r, ref in pairs]
    c_err = [rel(r.get("cot"), ref.get("cot")) for r, ref in pairs]
    rms = [scoring.rms_path_error_cm(np.array(r["path"]), np.array(r["path_t"]), np.array(ref["path"]),
                                     np.array(ref["path_t"])) if "path" in r and "path" in ref else math.inf
           for r, ref in pairs]
    return {
        "label": s.label, "group": s.group, "numerical": s.numerical, "overrides": s.overrides,
        "wall_s_per_sim_s": median(r["wall_s_per_sim_s"] for r in mine),
        "median_distance_error": median(d_err), "max_distance_error": max(d_err),
        "median_distance_error_cm": median(d_cm),
        "median_cot_error": median(c_err), "median_rms_path_error_cm": median(rms),
        "statuses": [r["status"] for r in mine], "reasons": [r["reason"] for r in mine if r["reason"]],
        "distance_errors": d_err,
    }


def _recommend(table: list[dict[str, Any]], front: list[str], floor: float) -> tuple[dict[str, Any], str]:
    """The fastest setting on the Pareto front within the chaos floor (at least 1 %), else the most accurate."""
    threshold = max(0.01, floor)
    ok = [r for r in table if r["label"] in front and r["median_distance_error"] <= threshold
          and all(st == "complete" for st in r["statuses"])]
    if ok:
        return (min(ok, key=lambda r: r["wall_s_per_sim_s"]),
                f"fastest setting on the Pareto front with median distance error <= {threshold:.2%}")
    return (min((r for r in table if r["numerical"]), key=lambda r: r["median_distance_error"]),
            f"no setting reaches {threshold:.2%}; the most accurate one")


def plot(report: dict[str, Any], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5))
    front = set(report["pareto_front"])
    for r in report["table"]:
        err = max(r["median_distance_error"], 1e-5)
        if not math.isfinite(err) or not math.isfinite(r["wall_s_per_sim_s"]):
            continue
        marker = "o" if r["numerical"] else "s"
        color = "tab:red" if r["label"] in front else ("tab:gray" if r["numerical"] else "tab:green")
        ax.scatter(r["wall_s_per_sim_s"], err, marker=marker, color=color)
        ax.annotate(r["label"], (r["wall_s_per_sim_s"], err), fontsize=7, xytext=(4, 2), textcoords="offset points")
    fr = sorted((r for r in report["table"] if r["label"] in front), key=lambda r: r["wall_s_per_sim_s"])
    ax.plot([r["wall_s_per_sim_s"] for r in fr], [max(r["median_distance_error"], 1e-5) for r in fr],
            color="tab:red", lw=1, label="Pareto front")
    ax.axhline(max(report["chaos_floor"], 1e-5), color="tab:blue", ls=":", label="chaos floor (1e-6 cm start jitter)")
    ax.axhline(0.01, color="k", ls="--", lw=0.8, label="1 % error")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall seconds per simulated second")
    ax.set_ylabel("median relative error of final distance")
    ax.set_title(f"{report['morphology']}: speed against error ({report['duration_s']:g} s trials); "
                 "squares: scenes (change, not error)", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def format_table(report: dict[str, Any]) -> str:
    lines = [f"{'setting':36s} {'wall/sim':>9s} {'dist err':>9s} {'(cm)':>8s} {'max':>9s} {'COT err':>9s} "
             f"{'RMS path':>9s}  status", "-" * 110]
    front = set(report["pareto_front"])
    for r in report["table"]:
        mark = "*" if r["label"] in front else " "
        bad = sum(s != "complete" for s in r["statuses"])
        lines.append(f"{mark}{r['label']:35s} {r['wall_s_per_sim_s']:9.3f} {r['median_distance_error']:9.2%} "
                     f"{r['median_distance_error_cm']:8.2f} "
                     f"{r['max_distance_error']:9.2%} {r['median_cot_error']:9.2%} "
                     f"{r['median_rms_path_error_cm']:8.2f}cm  {'ok' if not bad else f'{bad} not complete'}")
    refs = ", ".join(f"{r['distance_m'] * 100:.2f}" for r in report["reference"] if r["distance_m"] is not None)
    lines.append(f"reference distances (cm): {refs}; errors relative to max(reference, 1 cm)")
    lines.append(f"chaos floor {report['chaos_floor']:.2%}; * Pareto front; recommended: {report['recommended']} "
                 f"({report['recommendation_reason']})")
    return "\n".join(lines)
