"""A fit's losses as a run the project's workers serve: the fit's task in a RunConfig, and its evaluator.

A fit run's RunConfig holds the robot (spec), the trial config (engine, options, the starting profile) and, in
its `fit` field, the fitted recordings with their windows: every array as its float64 bytes (zlib, base64),
the rows no window reads replaced by copies (worker.fit.task._sent), so a worker's windows start and run from
the fitting process's states to the bit. A leased "trial" is one candidate: its
`params_unit` carries the candidate's values themselves, in the order of the run's parameter space (the fitted
constants with their bounds); not unit-cube points, since mapping there and back would not give the same bits.
The worker answers with the loss (worker.fit.loss.candidate_loss) in the result's extras, LOSS_KEY.
"""

from __future__ import annotations

import base64
import dataclasses
import math
import time
import zlib
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from spinefarm.protocol.errors import RunMismatchError
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.run import RunConfig
from spinefarm.protocol.states import TrialStatus
from spinefarm.protocol.work import TrialAssignment
from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.fit.fitting import with_values
from spinefarm.worker.fit.loss import Prepared, candidate_loss
from spinefarm.worker.fit.recording import Recording
from spinefarm.worker.fit.search import Bound
from spinefarm.worker.fit.state import engine_poses, velocities
from spinefarm.worker.fit.windows import Window

OBJECTIVE = "fit_loss"
LOSS_KEY = "fit_loss_cm"
_ARRAYS = ("time_s", "position_m", "quat_wxyz", "string_length_m", "rest_length_m", "tension_n")


def _array(a: np.ndarray) -> dict[str, Any]:
    a = np.ascontiguousarray(a, dtype="<f8")
    return {"shape": list(a.shape), "f8z": base64.b64encode(zlib.compress(a.tobytes(), 6)).decode("ascii")}


def _unarray(d: dict[str, Any]) -> np.ndarray:
    return np.frombuffer(zlib.decompress(base64.b64decode(d["f8z"])), dtype="<f8").reshape(d["shape"]).copy()


def _kept_rows(rec: Recording, windows: Sequence[Window]) -> np.ndarray:
    """The rows a window run reads: from the row before each start (its velocity, its strings' first rate) to two
    rows past its last checked one (the rest lengths interpolated over its steps)."""
    keep = np.zeros(len(rec.time_s), dtype=bool)
    for w in windows:
        keep[max(w.start - 1, 0):min(w.rows[-1] + 3, len(keep))] = True
    return keep


def _sent(rec: Recording, windows: Sequence[Window]) -> Recording:
    """The recording as sent: the rows no window reads hold copies of their neighbours (so they compress to
    nothing), quaternions with their signs already made continuous and, between kept stretches, one that agrees
    in sign with both ends (so the worker's own continuity pass flips nothing). The full recording instead if
    the kept rows' states would differ by a bit (checked here)."""
    keep = _kept_rows(rec, windows)
    if keep.all():
        return rec
    idx = np.maximum.accumulate(np.where(keep, np.arange(len(keep)), -1))
    idx = np.where(idx < 0, int(np.argmax(keep)), idx)   # rows before the first kept one: its copy
    q = engine_poses(rec)[..., [6, 3, 4, 5]]              # continuous signs, (w, x, y, z)
    quat = q[idx]
    for gap in np.flatnonzero(~keep[1:] & keep[:-1]) + 1:  # each gap after a kept stretch
        nxt = gap + int(np.argmax(keep[gap:])) if keep[gap:].any() else len(keep)
        if nxt < len(keep):
            mid = q[gap - 1] + q[nxt]
            quat[gap:nxt] = mid / np.linalg.norm(mid, axis=-1, keepdims=True)
    arrays = {k: getattr(rec, k)[idx] for k in ("position_m", "rest_length_m", "tension_n")
              if getattr(rec, k) is not None}
    sent = dataclasses.replace(rec, quat_wxyz=quat, string_length_m=None, **arrays)
    rows, starts = np.flatnonzero(keep), [w.start for w in windows]
    same = all(np.array_equal(a, b) for a, b in (
        (engine_poses(sent)[rows], engine_poses(rec)[rows]), (velocities(sent)[starts], velocities(rec)[starts]),
        (sent.rest_length_m[rows], rec.rest_length_m[rows])))
    return sent if same else rec


def _recording(p: Prepared) -> dict[str, Any]:
    rec = _sent(p.rec, p.windows)
    return {"name": p.name, "windows": [[w.start, list(w.rows)] for w in p.windows],
            "arrays": {k: _array(getattr(rec, k)) for k in _ARRAYS if getattr(rec, k) is not None},
            "drive": rec.drive, "scene": rec.scene, "source": rec.source, "morphology": rec.morphology}


def _prepared(d: dict[str, Any]) -> Prepared:
    arrays = {k: _unarray(v) for k, v in d["arrays"].items()}
    rec = Recording(**arrays, drive=d["drive"], scene=d["scene"], source=d["source"], morphology=d["morphology"])
    windows = [Window(int(s), tuple(int(r) for r in rows)) for s, rows in d["windows"]]
    return Prepared(d["name"], rec, windows, engine_poses(rec))


def fit_run_config(run_id: str, morph: Morphology, cfg: TrialConfig, fitted: Sequence[Prepared],
                   bounds: Sequence[Bound]) -> RunConfig:
    """The run a fit's workers serve: one trial per candidate, its loss over `fitted` under cfg."""
    space = tuple({"name": b.name, "low": b.low, "high": b.high, "unit": "", "doc": "a fitted constant"}
                  for b in bounds)
    return RunConfig(run_id, morph.name, morph.to_dict(), None, space, cfg.to_dict(), OBJECTIVE, 0,
                     spec_hash=morph.spec_hash(), trial_config_hash=cfg.config_hash(),
                     fit={"recordings": [_recording(p) for p in fitted]})


def simulated_s(fitted: Sequence[Prepared]) -> float:
    """Simulated seconds of one candidate's loss: every window's length (the worker's time limit scales by it)."""
    return float(sum(p.rec.time_s[w.rows[-1]] - p.rec.time_s[w.start] for p in fitted for w in p.windows))


def fit_evaluator(config: RunConfig) -> Callable[[TrialAssignment], TrialResult]:
    """A function of one leased candidate: its loss over the run's recordings, as this process would compute it.
    The robot and trial config are rebuilt from the run's data and must reproduce its hashes."""
    morph = Morphology.from_dict(config.morphology_spec)
    cfg = TrialConfig.from_dict(config.trial_config)
    for name, built in (("spec_hash", morph.spec_hash()), ("trial_config_hash", cfg.config_hash())):
        if getattr(config, name) != built:
            raise RunMismatchError(f"this worker cannot reproduce the fit's {name} (a different software version?)",
                                   received=built, expected=getattr(config, name))
    fitted = [_prepared(d) for d in config.fit["recordings"]]
    bounds = [Bound(p["name"], float(p["low"]), float(p["high"])) for p in config.param_space]

    def evaluate(a: TrialAssignment) -> TrialResult:
        t0 = time.perf_counter()
        if len(a.params_unit) != len(bounds) or not all(
                b.low <= v <= b.high for b, v in zip(bounds, a.params_unit, strict=False)):
            raise RunMismatchError("a fit candidate outside its bounds", received=list(a.params_unit),
                                   expected=[f"{b.name} in [{b.low:g}, {b.high:g}]" for b in bounds])
        values = {b.name: v for b, v in zip(bounds, a.params_unit, strict=True)}
        loss = candidate_loss(morph, with_values(cfg, values), fitted)
        return TrialResult(TrialStatus.COMPLETE, "", 0.0, 0.0, 0.0, 0.0, math.inf, simulated_s(fitted),
                           time.perf_counter() - t0, math.nan, a.seed, extras={LOSS_KEY: loss})

    return evaluate
