"""Gait pictures of stored trials, rendered on demand in a subprocess and cached on disk.

The API process never imports the simulator: `python -m spinefarm.worker.picture` re-simulates the trial and
draws the `render` strip. A picture is keyed by what determines it (run config, parameters, seed), so
it is rendered once; requests for one being drawn wait for it instead of starting another.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import math
import os
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

from spinefarm.api.errors import NotFound, RenderFailed, SimulatorUnavailable
from spinefarm.storage.schema import RunMeta, TrialRecord

FRAMES = 6
RENDER_TIMEOUT_S = 900.0
# The Python module each engine needs; a server without it says so instead of failing later.
ENGINE_MODULES = {"bullet": "pybullet", "mujoco": "mujoco"}


def default_cache_dir() -> Path:
    return Path(os.environ.get("SPINEFARM_CACHE_DIR") or Path(tempfile.gettempdir()) / "spinefarm-cache") / "pictures"


def simulator_missing(engine: str) -> str | None:
    """Why this process cannot draw a trial of `engine`, or None when it can."""
    for module in ("spinefarm.worker.trial", ENGINE_MODULES.get(engine, engine)):
        try:
            found = importlib.util.find_spec(module) is not None
        except (ImportError, ValueError):
            found = False
        if not found:
            return f"the simulator is not installed here (Python module {module!r} not found)"
    return None


class PictureCache:
    def __init__(self, cache_dir: Path | None = None) -> None:
        self.dir = Path(cache_dir) if cache_dir is not None else default_cache_dir()
        self._locks: dict[str, threading.Lock] = {}
        self._guard = threading.Lock()

    def _lock(self, key: str) -> threading.Lock:
        with self._guard:
            return self._locks.setdefault(key, threading.Lock())

    def picture(self, meta: RunMeta, rec: TrialRecord) -> Path:
        if not meta.morphology_spec:
            raise NotFound("this run has no gait to draw", received=meta.morphology,
                           expected="a run of a robot (its objective here is a test function)")
        if rec.status == "waiting":
            raise NotFound("this trial has not run yet", received=rec.trial_id, expected="a finished trial")
        engine = str(meta.trial_config.get("engine", "bullet"))
        missing = simulator_missing(engine)
        if missing:
            raise SimulatorUnavailable(f"cannot draw gaits: {missing}",
                                       expected="the API on a machine with `pip install spinefarm` complete")
        trial_config = dict(meta.trial_config)
        if math.isfinite(rec.duration_s):  # a multi-fidelity rung asks for its own duration
            trial_config["duration_s"] = rec.duration_s
        job = {"morphology": meta.morphology_spec, "controller": meta.controller,
               "trial_config": trial_config, "params_unit": list(rec.params_unit), "seed": rec.seed,
               "frames": FRAMES, "title": f"{meta.run_id} trial {rec.trial_id}"}
        key = hashlib.sha256(json.dumps({k: v for k, v in job.items() if k != "title"},
                                        sort_keys=True).encode()).hexdigest()[:32]
        out = self.dir / f"{key}.png"
        with self._lock(key):
            if out.is_file():
                return out
            self._render(job, out)
        return out

    def _render(self, job: dict, out: Path) -> None:
        self.dir.mkdir(parents=True, exist_ok=True)
        fd, job_path = tempfile.mkstemp(suffix=".json", dir=self.dir)
        with os.fdopen(fd, "w") as fh:
            json.dump(job, fh)
        tmp = out.with_name(out.stem + f".{os.getpid()}.tmp.png")
        try:
            # -P: the user's current folder never shadows the installed package in the drawing process
            r = subprocess.run([sys.executable, "-P", "-m", "spinefarm.worker.picture", job_path, str(tmp)],
                               capture_output=True, text=True, timeout=RENDER_TIMEOUT_S, stdin=subprocess.DEVNULL)
            if r.returncode != 0 or not tmp.is_file():
                last = (r.stderr.strip().splitlines() or ["no output"])[-1]
                raise RenderFailed("drawing the trial failed", received=last[:300], expected="a picture")
            os.replace(tmp, out)
        except subprocess.TimeoutExpired as exc:
            raise RenderFailed("drawing the trial took too long", received=f"{RENDER_TIMEOUT_S:.0f} s",
                               expected="a shorter trial") from exc
        finally:
            os.unlink(job_path)
            tmp.unlink(missing_ok=True)
