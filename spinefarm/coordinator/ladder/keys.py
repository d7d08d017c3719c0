"""Lease keys of the ladder's checks: a screen row leases under its row id (>= 0), a check (judge, audit,
referee, opinion) under a negative key naming its kind and the row it checks. Keys live only in the lease
scheduler: what is pending is stored in the run file (verdict columns, evaluation rows)."""

from __future__ import annotations

from spinefarm.protocol.states import EvaluationKind

JUDGE, AUDIT, REFEREE, OPINION = 1, 2, 3, 4
# a check's code in its key; the kinds themselves are protocol.states.EvaluationKind
KINDS = {JUDGE: EvaluationKind.JUDGE, AUDIT: EvaluationKind.AUDIT, REFEREE: EvaluationKind.REFEREE,
         OPINION: EvaluationKind.OPINION}
KIND_CODES = {kind: code for code, kind in KINDS.items()}
TRIAL = "trial"   # what split_key names a screen row's lease
_KEY_STRIDE = 8   # more than the kinds: a key's kind is its remainder


def check_key(kind: int, trial_id: int) -> int:
    return -(_KEY_STRIDE * trial_id + kind)


def split_key(key: int) -> tuple[str, int]:
    """(TRIAL, id) for a row, (its EvaluationKind, id of the row it checks) for a check."""
    if key >= 0:
        return TRIAL, key
    return KINDS[-key % _KEY_STRIDE], -key // _KEY_STRIDE
