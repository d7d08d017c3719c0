"""Gait pictures and motions of stored trials, re-simulated on demand in a subprocess and cached on disk.

The API process never imports the simulator: `python -m spinefarm.worker.tools.picture` re-simulates the trial and
draws the `render` strip, `python -m spinefarm.worker.tools.motion` records its motion for the 3D view. Each is
keyed by what determines it (run config, parameters, seed, the trial's length, engine and step), so it is
made once; requests for one being made wait for it instead of starting another.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import json
import logging
import math
import os
import subprocess
import sys
import tempfile
import threading
from pathlib import Path
from typing import Any

from spinefarm.api.errors import NotFound, RenderFailed, SimulatorUnavailable
from spinefarm.storage.schema import RunMeta, TrialRecord

log = logging.getLogger("spinefarm.api")
FRAMES = 6
RENDER_TIMEOUT_S = 900.0
# The Python module each engine needs; a server without it says so instead of failing later.
ENGINE_MODULES = {"bullet": "pybullet", "mujoco": "mujoco"}
# what each kind of drawing runs (python -m MODULE JOB OUT) and the file it writes
KINDS = {"picture": ("spinefarm.worker.tools.picture", ".png"), "motion": ("spinefarm.worker.tools.motion", ".json")}


def default_cache_dir() -> Path:
    return Path(os.environ.get("SPINEFARM_CACHE_DIR") or Path(tempfile.gettempdir()) / "spinefarm-cache") / "pictures"


def simulator_missing(engine: str) -> str | None:
    """Why this process cannot draw a trial of `engine`, or None when it can."""
    for module in ("spinefarm.worker.trial.simulation", ENGINE_MODULES.get(engine, engine)):
        try:
            found = importlib.util.find_spec(module) is not None
        except (ImportError, ValueError):
            found = False
        if not found:
            return f"the simulator is not installed here (Python module {module!r} not found)"
    return None


@functools.lru_cache(maxsize=1)
def code_stamp() -> str:
    """What the simulator's code is here (its files' sizes and times): a drawing cached by an older version
    of it is not served for a newer one."""
    spec = importlib.util.find_spec("spinefarm.worker")
    if spec is None or not spec.submodule_search_locations:
        return ""
    root = Path(next(iter(spec.submodule_search_locations)))
    stats = sorted((str(p.relative_to(root)), p.stat().st_size, p.stat().st_mtime_ns) for p in root.rglob("*.py"))
    return hashlib.sha256(repr(stats).encode()).hexdigest()[:16]


def trial_job(meta: RunMeta, rec: TrialRecord) -> dict[str, Any]:
    """What re-simulates a stored trial as it ran: the run's config with the trial's own length, settle,
    engine and step (a multi-fidelity rung's, a judge's). Raises when there is nothing to simulate."""
    if not meta.morphology_spec:
        raise NotFound("this run has no gait to draw", received=meta.morphology,
                       expected="a run of a robot (its objective here is a test function)")
    if rec.status == "waiting":
        raise NotFound("this trial has not run yet", received=rec.trial_id, expected="a finished trial")
    trial_config = {k: v for k, v in meta.trial_config.items() if k != "record_every_s"}
    for key, value in (("duration_s", rec.duration_s), ("settle_s", rec.settle_s), ("dt_s", rec.dt_s)):
        if math.isfinite(value):
            trial_config[key] = value
    if rec.engine:
        trial_config["engine"] = rec.engine
    engine = str(trial_config.get("engine", "bullet"))
    missing = simulator_missing(engine)
    if missing:
        raise SimulatorUnavailable(f"cannot draw gaits: {missing}",
                                   expected="the API on a machine with `pip install 'spinefarm[worker]'`")
    return {"morphology": meta.morphology_spec, "controller": meta.controller, "trial_config": trial_config,
            "params_unit": list(rec.params_unit), "seed": rec.seed, "frames": FRAMES,
            "title": f"{meta.run_id} trial {rec.trial_id}",
            **({"body": meta.run["body"]} if meta.run.get("body") else {})}  # a co-designed trial: its own body


class PictureCache:
    def __init__(self, cache_dir: Path | None = None) -> None:
        self.dir = Path(cache_dir) if cache_dir is not None else default_cache_dir()
        self._locks: dict[str, threading.Lock] = {}
        self._guard = threading.Lock()

    def _lock(self, key: str) -> threading.Lock:
        with self._guard:
            return self._locks.setdefault(key, threading.Lock())

    def picture(self, meta: RunMeta, rec: TrialRecord) -> Path:
        """The gait strip (PNG) of a stored trial, drawn from its recorded motion (one re-simulation for both)."""
        motion = self._cached(meta, rec, "motion")
        return self._cached(meta, rec, "picture", {"motion_file": str(motion)})

    def motion(self, meta: RunMeta, rec: TrialRecord) -> Path:
        """The trial's recorded motion (JSON, worker/tools/motion.py's format) for the 3D view."""
        return self._cached(meta, rec, "motion")

    def _cached(self, meta: RunMeta, rec: TrialRecord, kind: str, inputs: dict[str, Any] | None = None) -> Path:
        job = trial_job(meta, rec)
        key = hashlib.sha256(json.dumps({"kind": kind, "code": code_stamp(),
                                         **{k: v for k, v in job.items() if k != "title"}},
                                        sort_keys=True).encode()).hexdigest()[:32]
        out = self._writable_dir() / f"{key}{KINDS[kind][1]}"
        with self._lock(key):
            if out.is_file():
                return out
            self._render({**job, **(inputs or {})}, out, KINDS[kind][0])
        return out

    def _writable_dir(self) -> Path:
        """The cache folder; where it cannot be made (a read-only home, a path below a file) a private
        temporary one instead, said once in the log."""
        with self._guard:
            try:
                self.dir.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                fallback = Path(tempfile.mkdtemp(prefix="spinefarm-pictures-"))
                log.warning("cannot keep gait pictures in %s (%s); drawing them in %s", self.dir,
                            exc.strerror or exc, fallback)
                self.dir = fallback
            return self.dir

    def _render(self, job: dict, out: Path, module: str) -> None:
        try:
            fd, job_path = tempfile.mkstemp(suffix=".json", dir=out.parent)
            with os.fdopen(fd, "w") as fh:
                json.dump(job, fh)
        except OSError as exc:  # a full disk: the drawing fails in words, not with a traceback
            raise RenderFailed("cannot write in the picture cache", received=exc.strerror or str(exc),
                               expected=f"free space in {out.parent}") from exc
        tmp = out.with_name(out.stem + f".{os.getpid()}.tmp{out.suffix}")
        try:
            # -P: the user's current folder never shadows the installed package in the drawing process
            r = subprocess.run([sys.executable, "-P", "-m", module, job_path, str(tmp)],
                               capture_output=True, text=True, timeout=RENDER_TIMEOUT_S, stdin=subprocess.DEVNULL)
            if r.returncode != 0 or not tmp.is_file():
                last = (r.stderr.strip().splitlines() or ["no output"])[-1]
                raise RenderFailed("re-simulating the trial failed", received=last[:300], expected="its gait")
            os.replace(tmp, out)
        except subprocess.TimeoutExpired as exc:
            raise RenderFailed("drawing the trial took too long", received=f"{RENDER_TIMEOUT_S:.0f} s",
                               expected="a shorter trial") from exc
        finally:
            os.unlink(job_path)
            tmp.unlink(missing_ok=True)
