"""A robot's screening ladder: the rungs `search --engine auto` screens it with on MuJoCo when no `--rungs` are
given, as fractions of the trial, and the eta that goes with them (docs/morphology-format.md, "The screening
ladder"; the measured ones in docs/performance.md). A spec file carries its own in a `ladder:` block, or takes its
`base:` spec's (a block of its own replaces the base's whole, its `source` too); like the `search:` block it is
no part of the robot (its spec hash, and so its calibration, stay the same):

    ladder:
      rungs: [2/30, 5/30, 1]      # fractions of the trial, increasing, the last the whole trial
      eta: 3                      # keep the best 1/eta of each rung
      source: python bench/ladder.py ...   # the measurement it came from (optional)
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise
from pathlib import Path
from typing import Any

from spinefarm.protocol.errors import ConfigError
from spinefarm.protocol.settings import DEFAULT_ETA
from spinefarm.robot.morphology.specyaml import SpecSource, line_of, mapping, number

WHOLE_TOLERANCE = 1e-9  # the last fraction is 1 up to this (an expression such as 0.1 * 10 need not give 1.0)


@dataclass(frozen=True)
class RobotLadder:
    """fractions: each rung's length over the trial's, increasing, the last 1; eta: the best 1/eta of a rung go
    on; source: the measurement it came from ("" when not said); spec: the file that carries it ("": the default)."""

    fractions: tuple[float, ...]
    eta: int
    source: str = ""
    spec: str = ""

    def __post_init__(self) -> None:
        if problem := ladder_problem(self.fractions, self.eta):
            field, message, received, expected = problem
            raise ConfigError(f"{field}: {message}", received=received, expected=expected)

    @property
    def reason(self) -> str:
        """Why a search screens with it, in words."""
        if not self.spec:
            return "the default ladder: a sixth, a third and the whole trial"
        return f"the robot's {'measured ' if self.source else ''}ladder, {Path(self.spec).name}"

    def rungs(self, duration_s: float) -> str:
        """The rungs of a `duration_s` trial, as `--rungs` takes them (the last exactly the trial)."""
        return ",".join([f"{duration_s * x:g}" for x in self.fractions[:-1]] + [f"{duration_s:g}"])


def ladder_problem(fractions: tuple[float, ...], eta: Any) -> tuple[str, str, Any, str] | None:
    """What is wrong with a ladder (its field, why, what was received, what is expected), None when nothing."""
    f = fractions
    if not f or f[0] <= 0 or any(b <= a for a, b in pairwise(f)) or abs(f[-1] - 1.0) > WHOLE_TOLERANCE:
        return ("ladder.rungs", "not increasing fractions of the trial ending at the whole trial", list(f),
                "increasing fractions in (0, 1], the last 1, e.g. [2/30, 5/30, 1]")
    if isinstance(eta, bool) or not isinstance(eta, int) or eta < 2:
        return "ladder.eta", "out of range", eta, "an integer >= 2"
    return None


def parse_ladder(spec: SpecSource, value: Any, line: int | None) -> RobotLadder:
    """A `ladder:` block, checked; errors name the file, the line and the field."""
    block = mapping(spec, value, "ladder", line, allowed=("rungs", "eta", "source"), required=("rungs", "eta"))
    rungs = block["rungs"]
    if not isinstance(rungs, list) or not rungs:
        raise spec.fail(line_of(block, "rungs"), "ladder.rungs", "not a list of fractions of the trial",
                        received=rungs, expected="e.g. [2/30, 5/30, 1]")
    fractions = tuple(number(spec, v, "ladder.rungs", line_of(block, "rungs")) for v in rungs)
    if problem := ladder_problem(fractions, block["eta"]):
        field, message, received, expected = problem
        raise spec.fail(line_of(block, field.split(".")[1]), field, message, received=received, expected=expected)
    return RobotLadder(fractions, block["eta"], str(block.get("source") or ""), spec.source)


# a sixth of the trial, a third and the whole of it, eta 4 (5,10,30: the Tetraspine's measured ladder,
# docs/performance.md): every robot without a ladder of its own
DEFAULT_LADDER = RobotLadder((1 / 6, 1 / 3, 1.0), DEFAULT_ETA)

