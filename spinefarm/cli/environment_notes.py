"""Saying plainly when this environment differs from the one a run file records (`trial --run`,
`search --resume`)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any


def recorded_environment(path: str | Path) -> dict[str, Any] | None:
    """The environment a run file records (None for a file written before runs recorded one)."""
    from spinefarm.storage.hdf5 import Hdf5Storage

    store = Hdf5Storage.open_read(path)
    try:
        return store.run_meta().environment or None
    finally:
        store.close()


def note_environment(path: str | Path, recorded: dict[str, Any] | None) -> str:
    """Print to stderr how this environment differs from `recorded`, the one run file `path` holds (nothing when
    it does not); returns the message."""
    from spinefarm.protocol.environment import describe_differences

    message = describe_differences(recorded)
    if message:
        print(f"{path}: {message}", file=sys.stderr, flush=True)
    return message
