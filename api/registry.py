"""Which run files the API serves: explicit files and/or every *.h5 in a directory (rescanned)."""

from __future__ import annotations

import logging
from pathlib import Path

from api.errors import NotFound
from protocol.errors import StorageError
from storage.hdf5 import read_meta

log = logging.getLogger("spinefarm.api")


class RunRegistry:
    def __init__(self, files: list[Path], runs_dir: Path | None) -> None:
        self.files = [Path(f) for f in files]
        self.runs_dir = Path(runs_dir) if runs_dir is not None else None
        self._ids: dict[Path, str] = {}   # path -> run id (files never change their run id)

    def paths(self) -> list[Path]:
        found = list(self.files)
        if self.runs_dir is not None and self.runs_dir.is_dir():
            found += sorted(p for p in self.runs_dir.glob("*.h5") if p not in found)
        return found

    def runs(self) -> dict[str, Path]:
        out: dict[str, Path] = {}
        for p in self.paths():
            if p not in self._ids:
                try:
                    self._ids[p] = read_meta(p).run_id
                except StorageError as exc:
                    log.info("skipping %s: %s", p, exc)
                    continue
            out.setdefault(self._ids[p], p)
        return out

    def path_of(self, run_id: str) -> Path:
        runs = self.runs()
        if run_id not in runs:
            raise NotFound("no such run", received=run_id, expected=f"one of {sorted(runs)[:20]}")
        return runs[run_id]
