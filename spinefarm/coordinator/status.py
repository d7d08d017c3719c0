"""The coordinator's live status (written to RUN.h5.status.json for the API): counts, rate, ETA, the
state of the judge and the audits, and each worker with its engines, environment and audit figures."""

from __future__ import annotations

import time
from typing import Any

from spinefarm.coordinator.ladder.keys import split_key
from spinefarm.storage.ranking import evaluation_counts


def live_status(core: Any) -> dict[str, Any]:
    """JSON-able status of a CoordinatorCore (its lock held)."""
    study, scheduler = core.study, core.scheduler
    now, wall = core.clock(), time.time()
    rate = core.finish_rate()
    remaining = max(0, study.planned - study.n_finished)
    counts = study.storage.counts()
    return {
        "run_id": core.run_id,
        "state": "done" if core.done else ("failed" if core.failure else "running"),
        "failure": core.failure,
        "trials_budget": study.budget,
        "trials_planned": study.planned,
        **evaluation_counts(study.storage.columns(), study.storage.evaluations()),
        "trials_sampled": study.n_asked,
        "trials_complete": counts["complete"],
        "trials_failed": counts["failed"],
        "trials_leased": scheduler.n_leased,
        "trials_queued": scheduler.n_queued + max(0, study.planned - study.n_asked),
        "trials_reissued": scheduler.reissued,
        "tasks_pending": len(core.ladder.checks.pending),
        "checks_pending": _kinds(core.ladder.checks.pending),
        "fidelity_raised": core.drift,
        "audit": {**study.storage.audit_counts(), "environments": core.peers.environments(),
                  "comparisons": dict(core.ladder.audit_comparisons),
                  "unaudited": {str(t): why for t, why in core.unaudited.items()}},
        "coordinator": core.holder,
        "claimed_by": dict(core.claims),
        "code_digest": core.code_digest,
        "rate_trials_s": rate,
        "eta_s": (remaining / rate) if rate > 0 else None,
        "rejected_messages": core.rejected_messages,
        "forged_results": core.forged_results,
        "foreign_results": core.foreign_results,
        "unservable_workers": dict(core.unservable_workers),
        "dropped_results": dict(core.dropped_results),
        "workers": [{"worker_id": w.worker_id, "alive": w.alive, "leases": len(w.leases),
                     "last_contact_unix_s": wall - (now - w.last_contact_s), **core.peers.describe(w.worker_id)}
                    for w in scheduler.workers.values()],
        "updated_at_unix_s": wall,
    }


def _kinds(keys: set[int]) -> dict[str, int]:
    """How many pending checks of each kind (judge, audit, referee, opinion)."""
    out: dict[str, int] = {}
    for key in keys:
        kind = split_key(key)[0]
        out[kind] = out.get(kind, 0) + 1
    return out
