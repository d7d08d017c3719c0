"""The fit's loss and its report: the window error of a model against recordings, and the distance a whole
recording's drive carries the model.

Window error: the root mean square over every window, checked sample and segment of the pose error
(worker.fit.state.pose_error: COM position, plus rotation as the arc at the segment's radius), in cm. A window
that diverged counts as DIVERGED_CM at every later sample.

The fit's loss adds the strings' tensions when the recording has them: motion alone cannot tell a heavier robot
with stiffer, more damped strings from the original (with the strings driven by their rest lengths and contacts
that scale with the load, every acceleration stays the same: bench/fit.py --identify showed it), tensions can.
A tension error weighs TENSION_CM_PER_N cm per N in the loss.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from spinefarm.protocol.errors import ConfigError
from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.fit.recording import Recording
from spinefarm.worker.fit.state import engine_poses, planar_distance_cm, pose_error
from spinefarm.worker.fit.windows import Window, plan_windows, run_windows

DIVERGED_CM = 100.0
TENSION_CM_PER_N = 0.1  # a 10 N tension error weighs as a 1 cm pose error


@dataclass
class Prepared:
    """A recording with its windows and the recorded poses (engine terms) they are checked against."""

    name: str
    rec: Recording
    windows: list[Window]
    poses: np.ndarray  # (n, nb, 7) COM cm + quaternion (x, y, z, w)


def prepare(name: str, rec: Recording, window_s: float, stride_s: float, skip_s: float = 0.0) -> Prepared:
    return Prepared(name, rec, plan_windows(rec, window_s, stride_s, skip_s), engine_poses(rec))


def segment_radius_cm(morph: Morphology) -> float:
    """The RMS distance of segment 0's nodes from their centre: the radius a rotation error is weighed at."""
    nodes = morph.structure.node_array()[np.asarray(morph.structure.node_segment) == 0]
    return float(np.sqrt(((nodes - nodes.mean(axis=0)) ** 2).sum(axis=1).mean()))


def squared_errors(morph: Morphology, cfg: TrialConfig, p: Prepared, tensions: bool = False) -> np.ndarray:
    """Every checked sample's and segment's squared pose error (cm^2), flat; with `tensions` (and tensions in the
    recording) every checked string's squared tension error weighed by TENSION_CM_PER_N too."""
    radius = segment_radius_cm(morph)
    out = []
    for w, sim in zip(p.windows, run_windows(morph, cfg, p.rec, p.windows), strict=True):
        rows = list(w.rows)
        out.append(pose_error(sim.poses, p.poses[rows], radius).ravel())
        if tensions and p.rec.tension_n is not None:
            out.append((TENSION_CM_PER_N * (sim.tension_n - p.rec.tension_n[rows])).ravel())
    err = np.concatenate(out)
    return np.where(np.isfinite(err), err, DIVERGED_CM) ** 2


def window_error_cm(morph: Morphology, cfg: TrialConfig, recordings: list[Prepared]) -> float:
    """The RMS pose error (cm) over all windows of all these recordings."""
    if not recordings:
        return math.nan
    return float(np.sqrt(np.concatenate([squared_errors(morph, cfg, p) for p in recordings]).mean()))


def fit_loss(morph: Morphology, cfg: TrialConfig, recordings: list[Prepared]) -> float:
    """What the fit minimises: the RMS of the pose errors and the weighed tension errors (cm)."""
    return float(np.sqrt(np.concatenate([squared_errors(morph, cfg, p, True) for p in recordings]).mean()))


def candidate_loss(morph: Morphology, cfg: TrialConfig, recordings: list[Prepared]) -> float:
    """fit_loss, or DIVERGED_CM for constants the physics step cannot simulate (strings made too stiff or too
    damped for it): the search scores them as a diverged window and moves away, instead of stopping."""
    from spinefarm.robot.profile import apply_profile
    from spinefarm.worker.trial.episode import choose_step

    try:
        choose_step(apply_profile(morph, cfg.profile), cfg)
    except ConfigError:
        return DIVERGED_CM
    return fit_loss(morph, cfg, recordings)


def distances_cm(morph: Morphology, cfg: TrialConfig, p: Prepared) -> tuple[float, float]:
    """(recorded, simulated) horizontal distance (cm) of the scored segment over the whole recording, the model
    started from the recording's first state and driven by its rest lengths throughout."""
    last = len(p.rec.time_s) - 1
    sim = run_windows(morph, cfg, p.rec, [Window(0, (last,))])[0].poses[0]
    seg = morph.scored_segment
    return planar_distance_cm(p.poses[0, seg, :3], p.poses[last, seg, :3]), planar_distance_cm(
        p.poses[0, seg, :3], sim[seg, :3])


def report(morph: Morphology, cfg: TrialConfig, p: Prepared) -> dict[str, float]:
    recorded, simulated = distances_cm(morph, cfg, p)
    return {"window_error_cm": window_error_cm(morph, cfg, [p]), "distance_cm": simulated,
            "recorded_distance_cm": recorded}
