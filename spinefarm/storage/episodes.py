"""The episodes table of a robust run: one row per episode, keyed by (trial_id, episode).

A robust trial runs its parameter set in K randomised worlds (protocol.robust); the trial's row holds the
medians and the objective (a statistic over the episodes), this table every episode with its draw. Rows
are appended when the trial's result is stored, never changed. In a run file it is the group /episodes,
one resizable dataset per column; the writer writes a trial's episodes before its status, so a reader
that sees a finished trial sees its episodes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from spinefarm.protocol.columns import SCORE_PARTS, Column, column_group
from spinefarm.storage import side_table

# an episode's score parts, said of an episode where the trial's words do not fit
_EPISODE_WORDS = {"ntrt_distance_cm": "displacement of the segment NTRT scores",
                  "wall_time_s": "wall-clock time of the episode"}
EPISODE_COLUMNS: tuple[Column, ...] = (
    *column_group("episode"),
    *(replace(p, description=_EPISODE_WORDS.get(p.name, p.description)) for p in SCORE_PARTS
      if p.name != "mass_kg"),  # an episode records its draw (mass_scale), not the mass
    *column_group("draw"),
)
EPISODE_NAMES = tuple(c.name for c in EPISODE_COLUMNS)
GROUP = "episodes"


def empty_columns(n: int = 0) -> dict[str, np.ndarray]:
    return side_table.empty_columns(EPISODE_COLUMNS, n)


class EpisodeTable:
    """Growable episode columns; rows [n_written, n) are not in the file yet."""

    def __init__(self, capacity: int = 256) -> None:
        self.n = 0
        self.n_written = 0
        self._cols = empty_columns(capacity)

    def append(self, trial_id: int, episodes: Sequence[Any]) -> None:
        """Rows of one trial's episodes (protocol.robust.EpisodeResult)."""
        need = self.n + len(episodes)
        cap = len(self._cols["trial_id"])
        if need > cap:
            grown = empty_columns(max(need, 2 * cap))
            for name, arr in self._cols.items():
                grown[name][: self.n] = arr[: self.n]
            self._cols = grown
        for j, e in enumerate(episodes):
            i = self.n + j
            self._cols["trial_id"][i] = trial_id
            for c in EPISODE_COLUMNS[1:]:
                v = getattr(e, c.name)
                self._cols[c.name][i] = v.encode("utf-8", "replace")[: int(c.dtype[1:])] if c.dtype[0] == "S" else v
        self.n = need

    def columns(self) -> dict[str, np.ndarray]:
        return {name: arr[: self.n] for name, arr in self._cols.items()}

    def load(self, cols: dict[str, np.ndarray]) -> None:
        """Replace the contents with rows already in the file."""
        n = len(cols["trial_id"])
        self._cols = empty_columns(max(256, n))
        for name in EPISODE_NAMES:
            self._cols[name][:n] = cols[name]
        self.n = self.n_written = n


def rows_of(cols: dict[str, np.ndarray], trial_id: int) -> dict[str, np.ndarray]:
    """The episodes of one trial, in episode order."""
    idx = np.flatnonzero(cols["trial_id"] == trial_id)
    idx = idx[np.argsort(cols["episode"][idx], kind="stable")]
    return {name: arr[idx] for name, arr in cols.items()}


def of_finished(cols: dict[str, np.ndarray], status: np.ndarray, waiting: bytes) -> dict[str, np.ndarray]:
    """Only the episodes of trials that are stored as finished (a trial cut short before its status was
    written is run again on resume, and then stores its episodes again)."""
    tid = cols["trial_id"]
    ok = (tid >= 0) & (tid < len(status))
    ok[ok] &= status[tid[ok]] != waiting
    return {name: arr[ok] for name, arr in cols.items()}


# --- HDF5 ------------------------------------------------------------------------------------------
def create_datasets(f: Any, cols: dict[str, np.ndarray], compression: dict[str, Any]) -> None:
    side_table.create_group(f, GROUP, EPISODE_COLUMNS, cols, compression, chunk_rows=1024)


def read_datasets(f: Any) -> dict[str, np.ndarray]:
    """Every fully written episode row of an open file (none for a file from before episodes)."""
    return side_table.read_group(f, GROUP, EPISODE_COLUMNS)


def write_new(f: Any, table: EpisodeTable) -> None:
    """Append the rows not yet in the file (status last, so a half-written row is never read)."""
    if table.n == table.n_written:
        return
    side_table.append_rows(f, GROUP, table.columns(), table.n_written, table.n)
    table.n_written = table.n
