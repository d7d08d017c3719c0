"""How a run searches, typed and stored with the run: its fidelity ladder, judge, audit and leases.

A run's fidelities are a ladder of rungs. Each rung says how one evaluation is simulated (engine,
step, simulated duration, settle phase, episodes); a field left None takes the run's trial config.
The screening rungs are the search's own (the last one is the full trial); the judge is one more
rung that re-simulates new bests (the final one always). Workers run any rung's task like any trial.

RunSettings is stored in the run file as JSON (`RunSettings.SCHEMA` describes every field) and read
back with `RunSettings.from_dict`, which refuses unknown fields and wrong types with one line.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields
from itertools import pairwise
from typing import Any, ClassVar, TypeVar

from spinefarm.protocol.engine_choice import EngineChoice
from spinefarm.protocol.errors import ConfigError, bounded, check_fields, check_range
from spinefarm.protocol.states import EvaluationKind

SCHEDULERS = ("plain", "halving")
_R = TypeVar("_R", bound="_JsonRecord")


class _JsonRecord:
    """A frozen dataclass stored as a JSON object: `to_dict` gives its fields, `from_dict` refuses unknown
    fields with one line naming the record (WHAT)."""

    WHAT: ClassVar[str] = "record"

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)  # type: ignore[call-overload]  # every subclass is a dataclass

    @classmethod
    def from_dict(cls: type[_R], d: Any) -> _R:
        return cls(**_known(d, cls, cls.WHAT))


@dataclass(frozen=True)
class Rung(_JsonRecord):
    """One fidelity: engine (None: the run's), dt_s (None: the run's step), duration_s (None: the
    run's), settle_s (None: the run's), episodes (evaluations of one parameter set averaged)."""

    WHAT: ClassVar[str] = "rung"

    engine: str | None = None
    dt_s: float | None = None
    duration_s: float | None = None
    settle_s: float | None = None
    episodes: int = 1

    def __post_init__(self) -> None:
        if self.engine is not None and (not isinstance(self.engine, str) or not self.engine.isidentifier()):
            raise ConfigError("rung engine is not a name", received=self.engine, expected="e.g. bullet, mujoco")
        for name, low in (("dt_s", 1e-7), ("duration_s", 1e-6), ("settle_s", 0.0)):
            value = getattr(self, name)
            if value is not None:
                check_range(f"rung {name}", value, low, 1e6)
                object.__setattr__(self, name, float(value))
        if isinstance(self.episodes, bool) or not isinstance(self.episodes, int) or self.episodes < 1:
            raise ConfigError("rung episodes out of range", received=self.episodes, expected="an integer >= 1")


@dataclass(frozen=True)
class JudgePolicy(_JsonRecord):
    """The judge: re-simulate every new full-length best at `rung` before it counts.

    Same engine as the screen: the result holds when the distance changes by at most `tolerance`
    (relative; None: the robot's chaos floor, robot.chaos_floors), else it "moved" and ranks by the
    judge's distance. Another engine (two models, whose distances differ by more than any step error): the
    judge's distance is the one reported, the screen-to-judge ratio is stored, and the result fails
    only if the judge's run fails. perturb: also re-simulate with a jittered start pose and 10 % more
    friction. drift: a run whose judged ratios leave [1 - drift, 1 + drift] raises its fidelity. share: the
    most of the workers' time the judge takes while the search runs (its runs cost tens of trials each, and
    early bests are overtaken within seconds); the best at the search's end is always judged. opinion: the
    other engine's rung (at its converged step, OPINION_DT_S) each judged best is run once in, stored as an
    "opinion" evaluation (the models' spread; it never ranks); None: none."""

    WHAT: ClassVar[str] = "judge"

    enabled: bool = True
    rung: Rung = field(default_factory=Rung)
    tolerance: float | None = bounded(None, 0.0, 10.0, low_inclusive=False)
    perturb: bool = False
    drift: float = bounded(0.2, 0.0, 10.0, low_inclusive=False)
    share: float = bounded(0.25, 0.0, 1.0, low_inclusive=False)
    opinion: Rung | None = None

    def __post_init__(self) -> None:
        check_fields(self, "judge ")
        for name in ("rung", "opinion"):
            if isinstance(getattr(self, name), dict):
                object.__setattr__(self, name, Rung.from_dict(getattr(self, name)))
        if self.opinion is not None and (not isinstance(self.opinion, Rung) or self.opinion.engine is None):
            raise ConfigError("judge opinion is not a rung naming its engine", received=self.opinion,
                              expected="null or {engine, dt_s, ...}, e.g. {\"engine\": \"mujoco\", \"dt_s\": 0.001}")


@dataclass(frozen=True)
class AuditPolicy(_JsonRecord):
    """Re-simulate `fraction` of the results (and every new best) on another worker at the same
    fidelity; a relative distance difference above `tolerance` marks the result, its worker and that
    worker's environment. quarantine: a worker with a disagreeing audit gets no more leases."""

    WHAT: ClassVar[str] = "audit"

    fraction: float = bounded(0.0, 0.0, 1.0)
    tolerance: float = bounded(1e-6, 0.0, 10.0)
    quarantine: bool = True

    def __post_init__(self) -> None:
        check_fields(self, "audit ")

    @property
    def enabled(self) -> bool:
        return self.fraction > 0


# keep the best 1/eta of each rung: bench/ladder.py's choice (docs/performance.md, "A ladder chosen by measurement")
DEFAULT_ETA = 4

# The judge behind another screen engine: Bullet at its converged step (within ~1.5 % of a finer one,
# docs/accuracy.md); `search --verify-dt` defaults to it and the calibration takes it as its reference.
JUDGE_ENGINE = "bullet"
JUDGE_DT_S = 2.5e-4
# Each engine's converged step, where a judged best's second-engine opinion runs (docs/accuracy.md): Bullet
# ~1.5 % from a finer step at 0.25 ms; MuJoCo 0.46 % (median) at its 1 ms default, within max(1 %, chaos floor)
OPINION_DT_S = {"bullet": JUDGE_DT_S, "mujoco": 1e-3}


@dataclass(frozen=True)
class RunSettings:
    """scheduler: plain (every parameter set at the last rung) or halving (successive halving over the
    ladder, keeping 1/eta of each rung); ladder: the screening rungs, the last being the full trial;
    judge, audit: see their classes; lease_s: how long a worker may hold a task; engine_choice: how
    `--engine auto` chose the tier (None: the engine was given); enqueued: parameter sets (unit cube) given
    by the user, evaluated first and in order before the sampler proposes (`--enqueue`)."""

    scheduler: str = "plain"
    ladder: tuple[Rung, ...] = (Rung(),)
    eta: int = DEFAULT_ETA
    judge: JudgePolicy = field(default_factory=JudgePolicy)
    audit: AuditPolicy = field(default_factory=AuditPolicy)
    lease_s: float = 60.0
    engine_choice: EngineChoice | None = None
    enqueued: tuple[tuple[float, ...], ...] = ()

    SCHEMA: ClassVar[dict[str, str]] = {
        "scheduler": f"one of {', '.join(SCHEDULERS)}",
        "ladder": "list of rungs {engine, dt_s, duration_s, settle_s, episodes} (null: the run's), "
                  "increasing durations, the last the full trial",
        "eta": "integer >= 2: the halving scheduler keeps 1/eta of each rung",
        "judge": "{enabled, rung, tolerance, perturb, drift, share in (0, 1], opinion (null or a rung)}",
        "audit": "{fraction in [0, 1], tolerance >= 0, quarantine}",
        "lease_s": "seconds > 0",
        "engine_choice": "null, or how --engine auto chose the tier: {engine, mode, cached, rungs_added, "
                         "eta_added, ladder_reason, spearman, top_overlap, top_k, median_distance_ratio, n_moving, "
                         "n_random, n_bests, spec_hash, reason, tiers}",
        "enqueued": "list of parameter sets, each a list of numbers in [0, 1] (the unit cube), all one length",
    }

    def __post_init__(self) -> None:
        if self.scheduler not in SCHEDULERS:
            raise ConfigError("unknown scheduler", received=self.scheduler, expected=list(SCHEDULERS))
        ladder = tuple(r if isinstance(r, Rung) else Rung.from_dict(r) for r in self.ladder)
        object.__setattr__(self, "ladder", ladder)
        if not ladder:
            raise ConfigError("a run needs at least one rung", received=[], expected="one rung or more")
        durations = [r.duration_s for r in ladder]
        if len(ladder) > 1 and (None in durations or any(b <= a for a, b in pairwise(durations))):
            raise ConfigError("rungs must be increasing positive durations", received=durations,
                              expected="e.g. --rungs 10,30 (seconds; the last is the full trial)")
        if isinstance(self.eta, bool) or not isinstance(self.eta, int) or self.eta < 2:
            raise ConfigError("eta out of range", received=self.eta, expected="an integer >= 2")
        check_range("lease_s", self.lease_s, 0.0, low_inclusive=False)
        for name, cls in (("judge", JudgePolicy), ("audit", AuditPolicy)):
            if isinstance(getattr(self, name), dict):
                object.__setattr__(self, name, cls.from_dict(getattr(self, name)))
        if self.engine_choice is not None and not isinstance(self.engine_choice, EngineChoice):
            object.__setattr__(self, "engine_choice", EngineChoice.from_dict(self.engine_choice))
        object.__setattr__(self, "enqueued", _unit_sets(self.enqueued))

    @property
    def top(self) -> int:
        """Index of the full-length rung."""
        return len(self.ladder) - 1

    def rung(self, index: int) -> Rung:
        """Rung `index` of the ladder; -1 (or len(ladder)) is the judge's."""
        return self.judge.rung if index in (-1, len(self.ladder)) else self.ladder[index]

    def durations_s(self) -> tuple[float, ...]:
        return tuple(math.nan if r.duration_s is None else r.duration_s for r in self.ladder)

    def planned_evaluations(self, budget: int) -> int:
        """The budget of parameter sets, plus with halving about budget / eta^k promotions to rung k."""
        if self.scheduler != "halving":
            return budget
        return sum(budget // self.eta**k for k in range(len(self.ladder)))

    def to_dict(self) -> dict[str, Any]:
        return {"scheduler": self.scheduler, "ladder": [r.to_dict() for r in self.ladder], "eta": self.eta,
                "judge": self.judge.to_dict(), "audit": self.audit.to_dict(), "lease_s": self.lease_s,
                "engine_choice": None if self.engine_choice is None else self.engine_choice.to_dict(),
                "enqueued": [list(u) for u in self.enqueued]}

    @classmethod
    def from_dict(cls, d: Any) -> RunSettings:
        kw = _known(d, cls, "run settings")
        if "ladder" in kw:
            if not isinstance(kw["ladder"], list | tuple):
                raise ConfigError("run settings field 'ladder' is not a list", received=kw["ladder"],
                                  expected=cls.SCHEMA["ladder"])
            kw["ladder"] = tuple(Rung.from_dict(r) for r in kw["ladder"])
        return cls(**kw)


def _unit_sets(value: Any) -> tuple[tuple[float, ...], ...]:
    """Enqueued parameter sets as tuples of floats, each in the unit cube, all one length."""
    expected = RunSettings.SCHEMA["enqueued"]
    if not isinstance(value, list | tuple) or not all(isinstance(u, list | tuple) for u in value):
        raise ConfigError("run settings field 'enqueued' is not a list of lists", received=str(value)[:80],
                          expected=expected)
    sets = []
    for u in value:
        if not all(isinstance(x, int | float) and not isinstance(x, bool) and 0.0 <= x <= 1.0 for x in u):
            raise ConfigError("an enqueued parameter set is not in the unit cube", received=str(u)[:80],
                              expected=expected)
        sets.append(tuple(float(x) for x in u))
    if len({len(u) for u in sets}) > 1:
        raise ConfigError("enqueued parameter sets differ in length", received=sorted({len(u) for u in sets}),
                          expected=expected)
    return tuple(sets)


def _known(d: Any, cls: type, what: str) -> dict[str, Any]:
    """d as keyword arguments of cls: an object with known field names only."""
    if not isinstance(d, dict):
        raise ConfigError(f"{what} is not an object", received=type(d).__name__, expected="a JSON object")
    names = {f.name for f in fields(cls)}  # class-level constants (SCHEMA, WHAT) are no fields
    unknown = sorted(set(d) - names)
    if unknown:
        raise ConfigError(f"{what} has unknown fields", received=unknown, expected=sorted(names))
    try:
        return dict(d)
    except TypeError as exc:  # pragma: no cover - a dict always converts
        raise ConfigError(f"{what} is malformed", received=str(d)[:80], expected="a JSON object") from exc


PROMOTED = "promoted"   # the phase of a row that re-runs its parent at the next rung
ENQUEUED = "enqueued"   # the phase of a parameter set the user gave (--enqueue)
# a lease's task: a screen row, or a check at its fidelity (a referee runs as an audit does)
TASKS = ("trial", EvaluationKind.JUDGE.value, EvaluationKind.AUDIT.value, EvaluationKind.OPINION.value)


@dataclass(frozen=True)
class TaskFidelity(_JsonRecord):
    """How a worker runs one leased task, beyond the run's trial config: task (trial, judge, audit, opinion),
    engine / dt_s / settle_s (None: the run's), perturb (a jittered start pose and 10 % more friction,
    run besides the plain one: its distance comes back as the extra `perturbed_distance_m`)."""

    WHAT: ClassVar[str] = "task fidelity"

    task: str = "trial"
    engine: str | None = None
    dt_s: float | None = None
    settle_s: float | None = None
    perturb: bool = False

    def __post_init__(self) -> None:
        if self.task not in TASKS:
            raise ConfigError("unknown task", received=self.task, expected=list(TASKS))
        Rung(self.engine, self.dt_s, None, self.settle_s)  # the same checks as a rung's
        if not isinstance(self.perturb, bool):
            raise ConfigError("task field 'perturb' is not a boolean", received=self.perturb, expected="true/false")

    @classmethod
    def of(cls, task: str, rung: Rung, perturb: bool = False) -> TaskFidelity:
        return cls(task, rung.engine, rung.dt_s, rung.settle_s, perturb)
