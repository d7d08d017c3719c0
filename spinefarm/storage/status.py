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
    """Replace the status file atomically; a write that fails (a full disk) leaves the old one and no .tmp."""
    target = status_path(run_path)
    tmp = target.with_name(target.name + ".tmp")
    try:
        tmp.write_text(json.dumps(status, allow_nan=False, default=str))
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_final_status(run_path: str | Path, status: dict[str, Any]) -> str | None:
    """The coordinator's last status: None once written, else what went wrong. The old file would go on
    saying "running", so when the new one cannot be written (a full disk) the old one is removed and the write
    tried once more in the space it freed; failing that there is none, and readers take the state from the run
    file (api.run_state). Never raises OSError: every result is stored before this is written."""
    try:
        write_status(run_path, status)
        return None
    except OSError as exc:
        why = exc.strerror or str(exc)
    path = status_path(run_path)
    try:
        path.unlink(missing_ok=True)
    except OSError:  # a disk that died: nothing can be changed on it
        return f"cannot write the status file {path} ({why}); the old one stays"
    try:
        write_status(run_path, status)
    except OSError:
        return f"the disk is full ({why}): the status file {path} is left out (the run file says the state)"
    return f"the disk is full ({why}): the status file {path} was rewritten in the space of the old one"


def read_status(run_path: str | Path) -> dict[str, Any] | None:
    try:
        status = json.loads(status_path(run_path).read_text())
    except (OSError, ValueError):
        return None
    return _valid_text(status) if isinstance(status, dict) else None


def _valid_text(x: Any) -> Any:
    """Lone surrogates (JSON may spell "\ud800") cannot be served as UTF-8: replace them."""
    if isinstance(x, str):
        return x.encode("utf-8", "replace").decode("utf-8")
    if isinstance(x, dict):
        return {_valid_text(k): _valid_text(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_valid_text(v) for v in x]
    return x
