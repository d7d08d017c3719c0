"""Storage rows and status turned into JSON-ready dicts (named parameters, every score part)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from spinefarm.api.run_state import derive_state, live_figures, read_live
from spinefarm.protocol.columns import SCORE_NAMES
from spinefarm.protocol.states import JUDGED_VERDICTS
from spinefarm.storage.base import BaseStorage
from spinefarm.storage.codesign_coverage import run_coverage
from spinefarm.storage.evaluations import judged_cot
from spinefarm.storage.ranking import counted_distance_m, evaluation_counts, judged_speed_cm_s
from spinefarm.storage.schema import TrialRecord, json_number, older_file_note


def judge_of(meta: Any) -> str:
    """How the run re-simulates its bests: in another engine at its step, or at a finer step."""
    rung = meta.settings.judge.rung
    if rung.engine:
        return f"{rung.engine} at {1e3 * (rung.dt_s or 2.5e-4):g} ms"
    return "the search's engine at a finer step" + (f" ({1e3 * rung.dt_s:g} ms)" if rung.dt_s else "")


def verdict_label(rec: TrialRecord, meta: Any) -> str:
    """"holds" within the robot's chaos floor at the same engine, "moved X % at the finer step" beyond it; a
    cross-engine judgement: "judged in ENGINE"."""
    if rec.verification == "judged":
        return f"judged in {meta.settings.judge.rung.engine or 'the judge engine'}"
    if rec.verification == "moved" and rec.verify_reason:
        return rec.verify_reason.split(" (")[0]
    return rec.verification or "not_checked"


def verification_view(rec: TrialRecord, meta: Any) -> dict[str, Any]:
    """The judge's word on a set. `judge_distance_m` and its older name `fine_step_distance_m` (both interface,
    docs/distributed.md) are one value; `judged_speed_cm_s` is the speed the report shows (null unless judged)."""
    judge_m = json_number(rec.verify_distance_m)
    judged = rec.verification.encode() in JUDGED_VERDICTS and judge_m is not None
    return {"verdict": rec.verification or "not_checked", "label": verdict_label(rec, meta),
            "fine_step_distance_m": judge_m, "screen_distance_m": json_number(rec.distance_m),
            "judge_distance_m": judge_m, "screen_to_judge_ratio": json_number(rec.judge_ratio),
            "reason": rec.verify_reason or None, "judge": judge_of(meta),
            "counted_distance_m": json_number(counted_distance_m(rec.verification, rec.distance_m,
                                                                 rec.verify_distance_m)),
            "judged_speed_cm_s": json_number(judged_speed_cm_s(rec.verify_distance_m, rec.sim_time_s))
            if judged else None}


def trial_view(storage: BaseStorage, rec: TrialRecord) -> dict[str, Any]:
    meta = storage.run_meta()
    names = meta.param_names
    return {
        "trial_id": rec.trial_id, "status": rec.status, "reason": rec.reason, "phase": rec.phase,
        "parent": rec.parent if rec.parent >= 0 else None, "seed": rec.seed,
        "objective": json_number(rec.objective),
        "scores": {k: json_number(getattr(rec, k)) for k in SCORE_NAMES},
        "params": dict(zip(names, rec.params, strict=True)),
        "params_unit": dict(zip(names, rec.params_unit, strict=True)),
        "worker_id": rec.worker_id or None,
        "finished_at_unix_s": json_number(rec.finished_at_unix_s),
        "verification": verification_view(rec, meta),
        "audit": {"state": rec.audit or "not_audited", "distance_m": json_number(rec.audit_distance_m),
                  "worker_id": rec.audit_worker_id or None},
        "pareto_front": bool(rec.pareto_front),
        "engine": rec.engine or None, "dt_s": json_number(rec.dt_s), "settle_s": json_number(rec.settle_s),
        "rung": rec.rung, "duration_s": json_number(rec.duration_s),
    }


def judged_cot_view(rec: TrialRecord, evaluations: dict[str, np.ndarray]) -> dict[str, Any]:
    """{judged_cot, judged_cot_note}: the COT the judge's run measured on a judged set (holds, moved, judged), or
    null and why (not measured in a file from before it was stored); both null for a set not judged."""
    if rec.verification.encode() not in JUDGED_VERDICTS:
        return {"judged_cot": None, "judged_cot_note": None}
    cot, why = judged_cot(evaluations, rec.trial_id)
    return {"judged_cot": cot, "judged_cot_note": why}


def _noted(view: dict[str, Any], unaudited: dict[str, str]) -> dict[str, Any]:
    """A pending audit the coordinator could give to no other identity says so (the status file knows why)."""
    why = unaudited.get(str(view["trial_id"]))
    if why and view["audit"]["state"] == "pending":
        view["audit"]["note"] = why
    return view


def rung_lengths_s(settings: Any) -> list[float] | None:
    """A multi-fidelity run's trial lengths, short to full (None for a run of one length)."""
    if settings.scheduler != "halving" or len(settings.ladder) < 2:
        return None
    return [float(d) for d in settings.durations_s()]


def ladder_view(settings: Any) -> dict[str, Any] | None:
    """A multi-fidelity run's screening ladder, named as `spinefarm check --json` names a robot's (rungs as
    --rungs takes them, eta), and why it is this one: the reason `search --engine auto` stored with the ladder
    it added (the robot's own or the default; --eta given), else the rungs were typed (null for a ladder auto
    added before its reason was stored)."""
    lengths = rung_lengths_s(settings)
    if lengths is None:
        return None
    choice = settings.engine_choice
    auto = choice is not None and bool(choice.rungs_added)
    return {"rungs": ",".join(f"{d:g}" for d in lengths), "eta": settings.eta,
            "reason": (choice.ladder_reason or None) if auto else "typed (--rungs)", "engine_auto": auto}


def run_view(storage: BaseStorage, path: Path) -> dict[str, Any]:
    """The run's status from its file alone (state, counts, best, rate and ETA), with what only a live
    coordinator knows (leases, workers) from its status file when there is one. path: the file as the API
    was given it, for the commands that reopen or resume it."""
    meta = storage.run_meta()
    counts = storage.counts()
    live, status_error = read_live(path)
    age = time.time() - live.get("updated_at_unix_s", 0.0)
    finished = counts["complete"] + counts["failed"]
    planned = meta.settings.planned_evaluations(meta.trials_budget)
    n_trials = storage.n_trials()
    state = derive_state(path, n_trials, finished, planned, live, age)
    cols = storage.columns() if n_trials else {}
    finished_at = np.asarray(cols.get("finished_at_unix_s", []), dtype=float)
    steps = np.asarray(cols.get("dt_s", []), dtype=float)
    steps = steps[np.isfinite(steps)]
    best, pending = storage.reported_best(1)   # with auditing on: the best another identity's audit agreed with
    evaluations = storage.evaluations()
    unaudited = (live.get("audit") or {}).get("unaudited") or {}
    shown = str(path)
    tc = meta.trial_config
    return {
        "run_id": meta.run_id, "file": path.name, "morphology": meta.morphology,
        "file_schema_version": storage.file_schema_version, "file_note": older_file_note(storage.file_schema_version),
        "objective": meta.objective, "state": state, "trials_budget": meta.trials_budget,
        "trials_planned": planned,
        "parameter_sets_sampled": storage.count_rung(0),
        **(evaluation_counts(cols, evaluations) if n_trials
           else {"parameter_sets_done": 0, "evaluations_done": 0}),
        "best_distance_m": json_number(counted_distance_m(best[0].verification, best[0].distance_m,
                                                   best[0].verify_distance_m)) if best else None,
        "trials_done": finished, "trials_complete": counts["complete"], "trials_failed": counts["failed"],
        "trials_leased": live.get("trials_leased") if state == "running" else None,
        "trials_queued": live.get("trials_queued") if state == "running" else None,
        **live_figures(state, live, age, finished_at, max(0, planned - finished)),
        "best": _noted({**trial_view(storage, best[0]), **judged_cot_view(best[0], evaluations)}, unaudited)
        if best else None,
        "pending_audit": _noted(trial_view(storage, pending), unaudited) if pending is not None else None,
        # a finished run keeps the last the coordinator knew (who ran, who was quarantined); a stopped one shows none
        "workers": live.get("workers", []) if state in ("running", "stalled", "done") else [],
        "audit": {**storage.audit_counts(), "fraction": meta.settings.audit.fraction,
                  "tolerance": meta.settings.audit.tolerance,
                  "environments": (live.get("audit") or {}).get("environments", []),
                  "comparisons": (live.get("audit") or {}).get("comparisons", {}), "unaudited": unaudited},
        "claimed_by": live.get("claimed_by") or {},
        "fidelity_raised": live.get("fidelity_raised"),
        "codesign": run_coverage(meta, cols) if n_trials and meta.run.get("body") else None,
        "unservable_workers": (live.get("unservable_workers") or {}) if state in ("running", "stalled", "done") else {},
        "status_age_s": age if live else None,
        "status_file_error": status_error,
        "started_at_unix_s": json_number(meta.created_at_unix_s),
        "controller": meta.controller or (tc.get("controller") if tc else None),
        "engine": (tc.get("engine") or "bullet") if meta.morphology_spec else None,
        "step_s": float(np.median(steps)) if steps.size else None,
        "sampler": (meta.sampler or {}).get("name"),
        "rungs_s": rung_lengths_s(meta.settings), "ladder": ladder_view(meta.settings),
        "reopen_command": f"spinefarm api {shown}",
        "resume_command": f"spinefarm search --resume {shown}" if state in ("stopped", "failed", "empty") else None,
    }
