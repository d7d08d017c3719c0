"""What a window error is made of: per window, the pose error split into its terms, to tell a constant's error
(every term a little) from a structural one (one term, in one phase of the motion).

Terms per window (RMS over its checked samples and segments): the COM's horizontal and vertical (Y up) position
error (cm), the rotation as the arc it sweeps at the segment's radius (cm; worker.fit.state.pose_error) and,
when recorded, the strings' tension error (N). A diverged window counts as loss.DIVERGED_CM.
"""

from __future__ import annotations

import numpy as np

from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.fit.loss import DIVERGED_CM, Prepared, segment_radius_cm
from spinefarm.worker.fit.state import rotation_angle
from spinefarm.worker.fit.windows import run_windows

TERMS = ("horizontal_cm", "vertical_cm", "rotation_cm", "tension_n")


def _rms(x: np.ndarray) -> float:
    x = np.where(np.isfinite(x), x, DIVERGED_CM)
    return float(np.sqrt(np.mean(x**2)))


def window_terms(morph: Morphology, cfg: TrialConfig, p: Prepared) -> list[dict[str, float]]:
    """Per window of the recording: its start (s) and the RMS of each term (TERMS; tension NaN if unrecorded)."""
    radius = segment_radius_cm(morph)
    out = []
    for w, sim in zip(p.windows, run_windows(morph, cfg, p.rec, p.windows), strict=True):
        rec = p.poses[list(w.rows)]
        delta = sim.poses[..., :3] - rec[..., :3]
        tension = np.nan if p.rec.tension_n is None else _rms(sim.tension_n - p.rec.tension_n[list(w.rows)])
        out.append({"start_s": float(p.rec.time_s[w.start] - p.rec.time_s[0]),
                    "horizontal_cm": _rms(np.hypot(delta[..., 0], delta[..., 2])), "vertical_cm": _rms(delta[..., 1]),
                    "rotation_cm": _rms(radius * rotation_angle(sim.poses, rec)), "tension_n": tension})
    return out


def term_shares(rows: list[dict[str, float]]) -> dict[str, float]:
    """Each pose term's share of the summed squared pose error over these windows (they add up to 1)."""
    sq = {t: sum(r[t] ** 2 for r in rows) for t in TERMS[:3]}
    total = sum(sq.values())
    return {t: v / total if total else float("nan") for t, v in sq.items()}
