"""The Pareto front of speed (maximised) and cost of transport (minimised) among complete trials.

A trial is on the front when no other complete trial is at least as fast and at most as costly and
better in one of the two. Storage keeps a `pareto_front` column up to date as results arrive (one
new result can only join the front and push members off it), so the run file marks the members.
"""

from __future__ import annotations

import numpy as np

from spinefarm.protocol.states import TrialStatus

Number = float | np.ndarray  # a speed or a COT, or arrays of them


def candidates(status: np.ndarray, speed_cm_s: np.ndarray, cot: np.ndarray) -> np.ndarray:
    """Rows that take part: complete, with a finite speed and a COT that is a number (inf: no motion)."""
    return (status == TrialStatus.COMPLETE.stored) & np.isfinite(speed_cm_s) & ~np.isnan(cot)


def dominates(s_a: Number, c_a: Number, s_b: Number, c_b: Number) -> np.ndarray | bool:
    """a dominates b: at least as fast, at most as costly, better in one (element-wise on arrays)."""
    return (s_a >= s_b) & (c_a <= c_b) & ((s_a > s_b) | (c_a < c_b))


def front_mask(status: np.ndarray, speed_cm_s: np.ndarray, cot: np.ndarray) -> np.ndarray:
    """(n,) bool: front members among n rows, computed from scratch in O(n log n)."""
    ok = np.flatnonzero(candidates(status, speed_cm_s, cot))
    mask = np.zeros(len(status), dtype=bool)
    if ok.size == 0:
        return mask
    # fastest first, ties by lower COT: a row is on the front iff its COT is below every earlier one's,
    # or it equals the running minimum with the same speed (an exact duplicate of a member)
    order = ok[np.lexsort((cot[ok], -speed_cm_s[ok]))]
    best_cot, best_speed = np.inf, np.inf
    for i in order:
        s, c = speed_cm_s[i], cot[i]
        if c < best_cot or (c == best_cot and s == best_speed):
            mask[i] = True
            best_cot, best_speed = c, s
    return mask


def join_front(front_ids: np.ndarray, speed_cm_s: np.ndarray, cot: np.ndarray, new_id: int) -> tuple[bool, np.ndarray]:
    """A new candidate against the current front: (joins the front, ids it pushes off the front)."""
    s, c = speed_cm_s[new_id], cot[new_id]
    fs, fc = speed_cm_s[front_ids], cot[front_ids]
    if np.any(dominates(fs, fc, s, c)):
        return False, front_ids[:0]
    return True, front_ids[dominates(s, c, fs, fc)]
