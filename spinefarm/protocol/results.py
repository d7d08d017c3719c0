"""What a trial measured: TrialResult, whose score parts (SCORE_PARTS, protocol.columns) are declared once,
in columns.toml; messages, storage columns, API schemas and exports derive from them."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields, replace
from typing import Any

from spinefarm.protocol import limits
from spinefarm.protocol.columns import SCORE_NAMES
from spinefarm.protocol.errors import MessageError
from spinefarm.protocol.measured import MEASURED_NUMBERS, Measured
from spinefarm.protocol.robust import MAX_EPISODES, EpisodeResult
from spinefarm.protocol.states import TrialStatus


@dataclass(frozen=True)
class TrialResult(Measured):
    """What one trial measured. Distances are in the ground plane; units are in the names.

    distance_m: displacement of the whole robot's centre of mass.
    ntrt_distance_cm: displacement of the segment NTRT scores (spec section 5).
    work_j: work done shortening strings under tension (relaxation is passive).
    cot: work_j / (mass_kg * g * distance_m), dimensionless (inf when distance is 0).
    status: complete, or failed with `reason` (diverged: ..., error: ...); partial metrics kept.
    episodes: a robust run's episodes (protocol.robust), each in its own randomised world; the parts
    above are then their medians.
    """

    status: TrialStatus  # Measured's first field, typed as a trial's state; it keeps its place
    mass_kg: float
    seed: int
    trial_id: int = -1
    worker_id: str = ""
    extras: dict[str, float] = field(default_factory=dict)
    episodes: tuple[EpisodeResult, ...] = ()

    @property
    def ok(self) -> bool:
        return self.status == TrialStatus.COMPLETE

    @classmethod
    def failed(cls, reason: str, seed: int, trial_id: int = -1, wall_time_s: float = math.nan) -> TrialResult:
        """A failure with nothing measured (a trial that raised, was given up, or whose result was unreadable)."""
        parts = {**dict.fromkeys(MEASURED_NUMBERS, math.nan), "sim_time_s": 0.0, "wall_time_s": wall_time_s}
        return cls(status=TrialStatus.FAILED, reason=reason, **parts, mass_kg=math.nan, seed=seed, trial_id=trial_id)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["status"] = str(self.status)
        if not self.episodes:
            del d["episodes"]
        return d

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TrialResult:
        if not isinstance(data, dict):
            raise MessageError("trial result is not an object", received=type(data).__name__,
                               expected="a JSON object")
        kwargs: dict[str, Any] = {}
        for f in fields(cls):
            if f.name not in data:
                if f.name in ("trial_id", "worker_id", "extras", "episodes"):
                    continue
                raise MessageError(f"trial result lacks field {f.name!r}", received=sorted(data),
                                   expected=[g.name for g in fields(cls)])
            kwargs[f.name] = data[f.name]
        try:
            kwargs["status"] = TrialStatus(kwargs["status"])
        except ValueError as exc:
            raise MessageError("trial result has an unknown status", received=kwargs["status"],
                               expected=[s.value for s in TrialStatus]) from exc
        for name in SCORE_NAMES:
            v = kwargs[name]
            if isinstance(v, bool) or not isinstance(v, int | float):
                raise MessageError(f"trial result field {name!r} is not a number", received=v,
                                   expected="a number")
            kwargs[name] = float(v)
        for name in ("seed", "trial_id"):
            if name in kwargs and (isinstance(kwargs[name], bool) or not isinstance(kwargs[name], int)):
                raise MessageError(f"trial result field {name!r} is not an integer", received=kwargs[name],
                                   expected="an integer")
        limits.check_text(kwargs["reason"], "trial result field 'reason'")
        if kwargs.get("worker_id"):
            limits.check_id(kwargs["worker_id"], "trial result field 'worker_id'")
        if not _extras_ok(kwargs.get("extras", {})):
            raise MessageError("trial result field 'extras' is malformed", received=str(kwargs["extras"])[:80],
                               expected=f"at most {limits.MAX_EXTRAS} name: number or short text pairs")
        episodes = kwargs.get("episodes", [])
        if not isinstance(episodes, list | tuple) or len(episodes) > MAX_EPISODES:
            raise MessageError("trial result field 'episodes' is malformed", received=str(episodes)[:80],
                               expected=f"a list of at most {MAX_EPISODES} episode results")
        kwargs["episodes"] = tuple(EpisodeResult.from_dict(e) for e in episodes)
        return cls(**kwargs)


MAX_EXTRA_TEXT_CHARS = 64   # a text in TrialResult.extras (a note on how the trial was computed)


def _cut(text: str, max_chars: int) -> str:
    return text if len(text) <= max_chars else text[:max_chars - 1] + "…"


def fit_extras(extras: dict[str, Any]) -> dict[str, Any]:
    """`extras` with every text cut to what the protocol carries (ending in "…")."""
    return {k: _cut(v, MAX_EXTRA_TEXT_CHARS) if isinstance(v, str) else v for k, v in extras.items()}


def fit_for_protocol(result: TrialResult) -> TrialResult:
    """`result` with its failure reason and notes cut to what the protocol carries: one long text (an
    exception's message, an engine's note) must not make the coordinator refuse the worker's whole batch."""
    return replace(result, reason=_cut(result.reason, limits.MAX_TEXT_CHARS), extras=fit_extras(result.extras))


def _extras_ok(extras: Any) -> bool:
    def value_ok(v: Any) -> bool:
        if isinstance(v, str):
            return len(v) <= MAX_EXTRA_TEXT_CHARS
        return isinstance(v, int | float) and not isinstance(v, bool)

    return (isinstance(extras, dict) and len(extras) <= limits.MAX_EXTRAS
            and all(isinstance(k, str) and len(k) <= 32 and value_ok(v) for k, v in extras.items()))

