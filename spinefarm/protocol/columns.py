"""The catalogue of stored quantities: every column a run file keeps is one line of columns.toml, read here
into Columns by group (the score parts, the recorded extras, each table's own)."""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Column:
    """A named quantity with its numpy dtype and unit: a part of a trial's score, an extra it records,
    and every column storage keeps (the trials and episodes tables) are declared as one, in columns.toml."""

    name: str
    dtype: str   # numpy dtype ("f8"; "S16": a short string, fixed-width bytes in files)
    unit: str
    description: str


def column_group(name: str) -> tuple[Column, ...]:
    """A group of columns.toml, in its order."""
    return tuple(Column(column, *about) for column, about in _CATALOGUE[name].items())


_CATALOGUE = tomllib.loads(Path(__file__).with_name("columns.toml").read_text(encoding="utf-8"))
# The measured parts of a trial's score: messages, storage columns, API schemas and exports derive from them.
SCORE_PARTS = column_group("score")
SCORE_NAMES = tuple(p.name for p in SCORE_PARTS)
# TrialResult.extras entries that storage keeps as columns: how the trial was computed.
RECORDED_EXTRAS = column_group("recorded")
