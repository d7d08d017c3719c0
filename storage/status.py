"""The live status sidecar: RUN.h5.status.json, rewritten atomically by the coordinator.

What lives only in the coordinator's memory (leases, queue, rate, workers and their last contact)
cannot go into an SWMR file (no new attributes once SWMR starts), so it goes here for readers.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any


def status_path(run_path: str | Path) -> Path:
    p = Path(run_path)
    return p.with_name(p.name + ".status.json")


def write_status(run_path: str | Path, status: dict[str, Any]) -> None:
    target = status_path(run_path)
    tmp = target.with_name(target.name + ".tmp")
    tmp.write_text(json.dumps(status, allow_nan=False, default=str))
    os.replace(tmp, target)


def read_status(run_path: str | Path) -> dict[str, Any] | None:
    try:
        return json.loads(status_path(run_path).read_text())
    except (OSError, ValueError):
        return None
