"""A run's state from its file alone: is a coordinator writing it now, is its budget met, did it stop early.

The live status sidecar (RUN.h5.status.json) adds what only the coordinator's memory holds (leases, workers),
but a copied run file, or one whose coordinator was killed, shows its real state without it.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ValidationError

from spinefarm.api.schemas import Worker
from spinefarm.storage.runlock import lock_path
from spinefarm.storage.status import read_status, status_path

# A status file not rewritten for this long, while its coordinator still holds the file, means it is stuck.
STALE_STATUS_S = 10.0
# The rate of a running search without a status file: the last finished trials, over at most this window.
RATE_TRIALS = 50


class LiveStatus(BaseModel):
    """What run_view takes from the status sidecar, with the types it serves them as (other keys pass)."""

    state: Literal["running", "done", "failed", "stopped"] = "running"  # what a coordinator writes
    updated_at_unix_s: float = 0.0
    trials_leased: int | None = None
    trials_queued: int | None = None
    rate_trials_s: float | None = None
    eta_s: float | None = None
    workers: list[Worker] = []
    audit: dict[str, Any] | None = None
    fidelity_raised: str | None = None
    unservable_workers: dict[str, str] | None = None


def read_live(run_path: Path) -> tuple[dict[str, Any], str | None]:
    """The status sidecar if it is well formed, else ({}, why): a hand-edited or foreign one is set aside
    (the run's state then comes from its file alone) and named, never served half-valid."""
    live = read_status(run_path)
    if not live:
        return {}, None
    try:
        LiveStatus.model_validate(live)
        environments = (live.get("audit") or {}).get("environments", [])
        if not isinstance(environments, list):
            raise ValueError(f"audit.environments is {type(environments).__name__}, not a list")
    except (ValidationError, ValueError) as exc:
        first = exc.errors()[0] if isinstance(exc, ValidationError) else {"loc": (), "msg": str(exc)}
        where = ".".join(str(x) for x in first["loc"]) or "the file"
        return {}, (f"status file {status_path(run_path)} is malformed and left out: {where}: {first['msg']}; "
                    f"received {str(first.get('input', ''))[:80]!r}")
    return live, None


def writer_holds(run_path: str | Path) -> bool:
    """Whether a process holds the run file's writer lock (the flock on RUN.h5.lock) right now.

    Read from /proc/locks, so no lock is taken (taking one, even shared, could make a starting
    coordinator fail); elsewhere, whether the pid the lock file names is alive."""
    lock = lock_path(run_path)
    try:
        inode = lock.stat().st_ino
    except OSError:
        return False  # never locked here: a copied file, or one written elsewhere
    try:
        table = Path("/proc/locks").read_text()
    except OSError:
        return _pid_alive(lock)
    for line in table.splitlines():
        parts = line.split()
        # "1: FLOCK  ADVISORY  WRITE 4242 00:2f:123456 0 EOF"; a waiter's line has "->" after the number
        if len(parts) >= 6 and parts[1] == "FLOCK" and parts[5].rsplit(":", 1)[-1] == str(inode):
            return True
    return False


def _pid_alive(lock: Path) -> bool:
    try:
        pid = int(lock.read_text().split()[0])
        os.kill(pid, 0)
    except (OSError, ValueError, IndexError):
        return False
    return True


def derive_state(run_path: Path, n_trials: int, finished: int, planned: int, live: dict[str, Any],
                 age_s: float) -> str:
    """running | stalled | done | stopped | failed | empty, from the file, its lock and (if fresh) the sidecar."""
    if writer_holds(run_path):
        if not live:
            return "running"
        if age_s > STALE_STATUS_S:
            return "stalled"
        return str(live.get("state", "running"))
    if live.get("state") == "failed":
        return "failed"
    if n_trials == 0:
        return "empty"
    return "done" if finished >= planned else "stopped"


def rate_from_file(finished_at_unix_s: np.ndarray) -> float | None:
    """Trials per second over the last RATE_TRIALS finished trials (None with fewer than two)."""
    t = np.sort(finished_at_unix_s[np.isfinite(finished_at_unix_s)])[-RATE_TRIALS:]
    if len(t) < 2 or t[-1] <= t[0]:
        return None
    return float((len(t) - 1) / (t[-1] - t[0]))


def live_figures(state: str, live: dict[str, Any], age_s: float, finished_at: np.ndarray, remaining: int
                 ) -> dict[str, Any]:
    """Rate and ETA: the coordinator's while it runs with a fresh sidecar, else from the file's timestamps
    (an ETA only while running)."""
    fresh = bool(live) and age_s <= STALE_STATUS_S and state == "running"
    if fresh:
        return {"rate_trials_s": live.get("rate_trials_s"), "eta_s": live.get("eta_s")}
    rate = rate_from_file(finished_at)
    if state in ("running", "stalled") and rate:
        recent = np.nanmax(finished_at) if np.isfinite(finished_at).any() else time.time()
        return {"rate_trials_s": rate, "eta_s": max(0.0, remaining / rate - (time.time() - recent))}
    return {"rate_trials_s": rate, "eta_s": None}
