"""What one run of a world measured: a trial's result (protocol.results.TrialResult) and each robust
episode's (protocol.robust.EpisodeResult) carry these fields, in this order, on the wire and in their
constructors.

Measured's fields are status, reason, then the score parts of columns.toml in their order (each a float,
units in the names), less those of the robot rather than of its world (mass_kg: a trial carries the
robot's mass, an episode the factor it drew): a new score part is its line in columns.toml alone.
"""

from __future__ import annotations

from dataclasses import make_dataclass

from spinefarm.protocol.columns import SCORE_NAMES

_OF_THE_ROBOT = ("mass_kg",)
MEASURED_NUMBERS = tuple(name for name in SCORE_NAMES if name not in _OF_THE_ROBOT)
Measured = make_dataclass("Measured", [("status", str), ("reason", str), *((n, float) for n in MEASURED_NUMBERS)],
                          frozen=True)
Measured.__module__ = __name__
Measured.__doc__ = ("status: complete or failed, with `reason` (diverged: ..., error: ...); then the parts of "
                    "the score (MEASURED_NUMBERS). A dataclass deriving from it lists its own fields after these.")


def measured_numbers(record: object) -> dict[str, float]:
    """The measured parts of a result or an episode, by name: what one hands the other's constructor."""
    return {name: getattr(record, name) for name in MEASURED_NUMBERS}
