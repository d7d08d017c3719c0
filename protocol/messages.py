"""Messages that cross process boundaries, encoded as JSON with a schema version.

Every decoded message is validated: a wrong schema version, a missing field or a field of
the wrong kind raises MessageError naming what was received and what was expected.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, fields
from enum import StrEnum
from typing import Any

from spinefarm.protocol import limits
from spinefarm.protocol.errors import ConfigError, MessageError
from spinefarm.protocol.robust import MAX_EPISODES, EpisodeResult
from spinefarm.protocol.settings import TaskFidelity

SCHEMA_VERSION = 1


class TrialStatus(StrEnum):
    """waiting -> running -> complete | failed(reason). Finished trials never change."""

    WAITING = "waiting"
    RUNNING = "running"
    COMPLETE = "complete"
    FAILED = "failed"

    @property
    def stored(self) -> bytes:
        """The value as the fixed-width byte string storage columns hold."""
        return self.value.encode()


STORED_STATUSES = (TrialStatus.WAITING, TrialStatus.COMPLETE, TrialStatus.FAILED)


class Verification(StrEnum):
    """Re-simulation of a trial that became best, at a finer step. A not-reproduced trial never
    counts as best."""

    NOT_CHECKED = ""
    PENDING = "pending"
    HOLDS = "holds"              # same engine, within tolerance
    JUDGED = "judged"            # in another engine: the judge's distance counts
    NOT_REPRODUCED = "not_reproduced"

    @property
    def stored(self) -> bytes:
        return self.value.encode()


class AuditState(StrEnum):
    """Re-simulation of a result by another worker at the same fidelity."""

    NOT_AUDITED = ""
    PENDING = "pending"
    AGREES = "agrees"            # the auditor measured the same
    DISPUTED = "disputed"        # they differ: a third worker referees
    DISAGREES = "disagrees"      # the referee sided with the auditor: the result (and its worker) is wrong
    OVERRULED = "overruled"      # the referee sided with the result: the auditor is wrong

    @property
    def stored(self) -> bytes:
        return self.value.encode()


@dataclass(frozen=True)
class ScorePart:
    """One measured part of a trial's score: messages, storage columns, API schemas and exports all
    derive from SCORE_PARTS, so a part is declared here once."""

    name: str
    unit: str
    description: str


SCORE_PARTS: tuple[ScorePart, ...] = (
    ScorePart("distance_m", "m", "displacement of the robot's centre of mass in the ground plane"),
    ScorePart("ntrt_distance_cm", "cm", "displacement of the segment NTRT scores, from the start pose"),
    ScorePart("speed_cm_s", "cm/s", "mean ground speed"),
    ScorePart("work_j", "J", "actuator work shortening strings under tension"),
    ScorePart("cot", "1", "cost of transport, work / (m g d)"),
    ScorePart("mass_kg", "kg", "robot mass"),
    ScorePart("sim_time_s", "s", "simulated time"),
    ScorePart("wall_time_s", "s", "wall-clock time the worker spent on the trial"),
)
SCORE_NAMES = tuple(p.name for p in SCORE_PARTS)


@dataclass(frozen=True)
class ExtraPart:
    """A TrialResult.extras entry that storage keeps as a column: how the trial was computed."""

    name: str
    dtype: str   # numpy dtype of the column ("f8", or "S16" for a short string)
    unit: str
    description: str


RECORDED_EXTRAS: tuple[ExtraPart, ...] = (
    ExtraPart("engine", "S16", "", "physics engine that ran the trial (bullet, mujoco)"),
    ExtraPart("dt_s", "f8", "s", "physics step the trial used (the automatic choice under --dt auto)"),
    ExtraPart("settle_s", "f8", "s", "settle phase before locomotion was scored (0: scored from the start)"),
    ExtraPart("time_limit_s", "f8", "s", "wall-clock limit the worker gave the trial (past it: failed, timeout)"),
)


@dataclass(frozen=True)
class TrialResult:
    """What one trial measured. Distances are in the ground plane; units are in the names.

    distance_m: displacement of the whole robot's centre of mass.
    ntrt_distance_cm: displacement of the segment NTRT scores (spec section 5).
    work_j: work done shortening strings under tension (relaxation is passive).
    cot: work_j / (mass_kg * g * distance_m), dimensionless (inf when distance is 0).
    status: complete, or failed with `reason` (diverged: ..., error: ...); partial metrics kept.
    episodes: a robust run's episodes (protocol.robust), each in its own randomised world; the parts
    above are then their medians.
    """

    status: TrialStatus
    reason: str
    distance_m: float
    ntrt_distance_cm: float
    speed_cm_s: float
    work_j: float
    cot: float
    sim_time_s: float
    wall_time_s: float
    mass_kg: float
    seed: int
    trial_id: int = -1
    worker_id: str = ""
    extras: dict[str, float] = field(default_factory=dict)
    episodes: tuple[EpisodeResult, ...] = ()

    @property
    def ok(self) -> bool:
        return self.status == TrialStatus.COMPLETE

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


def _extras_ok(extras: Any) -> bool:
    def value_ok(v: Any) -> bool:
        if isinstance(v, str):
            return len(v) <= 64
        return isinstance(v, int | float) and not isinstance(v, bool)

    return (isinstance(extras, dict) and len(extras) <= limits.MAX_EXTRAS
            and all(isinstance(k, str) and len(k) <= 32 and value_ok(v) for k, v in extras.items()))


def _json_default(obj: Any) -> Any:
    import numpy as np

    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"cannot encode {type(obj).__name__}")


def _finite_or_str(x: Any) -> Any:
    # JSON has no inf/nan: encode them as strings so every peer can parse the message.
    if isinstance(x, float) and not math.isfinite(x):
        return repr(x)
    if isinstance(x, dict):
        return {k: _finite_or_str(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_finite_or_str(v) for v in x]
    return x


def _restore_floats(x: Any) -> Any:
    if isinstance(x, str) and x in ("inf", "-inf", "nan"):
        return float(x)
    if isinstance(x, dict):
        return {k: _restore_floats(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_restore_floats(v) for v in x]
    return x


def encode(kind: str, body: dict[str, Any]) -> bytes:
    """Wrap `body` in an envelope {schema, kind, body} and encode it as UTF-8 JSON."""
    envelope = {"schema": SCHEMA_VERSION, "kind": kind, "body": _finite_or_str(body)}
    return json.dumps(envelope, default=_json_default, separators=(",", ":")).encode()


def decode(payload: bytes | str, expected_kind: str | None = None) -> tuple[str, dict[str, Any]]:
    """Return (kind, body) of an envelope; raise MessageError for anything malformed or foreign."""
    envelope = limits.loads(payload)  # size, nesting, integer digits and finiteness bounded
    if not isinstance(envelope, dict) or not {"schema", "kind", "body"} <= set(envelope):
        got = sorted(envelope) if isinstance(envelope, dict) else type(envelope).__name__
        raise MessageError("message is not a spinefarm envelope", received=got,
                           expected="an object with keys schema, kind, body")
    if type(envelope["schema"]) is not int or envelope["schema"] != SCHEMA_VERSION:  # not 1.0, not true
        raise MessageError("message has another schema version", received=envelope["schema"],
                           expected=SCHEMA_VERSION)
    kind = envelope["kind"]
    if expected_kind is not None and kind != expected_kind:
        raise MessageError("message is of another kind", received=kind, expected=expected_kind)
    if not isinstance(envelope["body"], dict):
        raise MessageError("message body is not an object", received=type(envelope["body"]).__name__,
                           expected="a JSON object")
    return kind, _restore_floats(envelope["body"])


# --- Distributed search messages (worker <-> coordinator over Zenoh) ---------------------------------

_MAX_BATCH = 4096


def _field(data: Any, name: str, kinds: type | tuple[type, ...], what: str) -> Any:
    """data[name] checked against `kinds` (bool is never accepted as a number)."""
    if not isinstance(data, dict):
        raise MessageError(f"{what} is not an object", received=type(data).__name__, expected="a JSON object")
    if name not in data:
        raise MessageError(f"{what} lacks field {name!r}", received=sorted(data), expected=f"field {name!r}")
    value = data[name]
    numeric = kinds in (int, float, (int, float))
    if (numeric and isinstance(value, bool)) or not isinstance(value, kinds):
        names = kinds.__name__ if isinstance(kinds, type) else " or ".join(k.__name__ for k in kinds)
        raise MessageError(f"{what} field {name!r} has the wrong type", received=value, expected=names)
    return value


def _finite(value: float, name: str, what: str) -> float:
    if not math.isfinite(value):
        raise MessageError(f"{what} field {name!r} is not finite", received=value, expected="a finite number")
    return float(value)


@dataclass(frozen=True)
class WorkRequest:
    """A worker asks a run for up to `capacity` trials, returning finished ones on the way.

    results: finished trials carried with the request (saves a round trip per batch); the grant's
    verdicts acknowledge them exactly as a ResultAck would.
    """

    KIND = "work_request"
    worker_id: str
    capacity: int
    results: tuple[SubmittedResult, ...] = ()
    engines: tuple[str, ...] | None = None      # the engines this worker can run (None: not said)
    environment: dict[str, str] | None = None   # what this worker runs on (python, packages, CPU)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"worker_id": self.worker_id, "capacity": self.capacity,
                             "results": [r.to_dict() for r in self.results]}
        if self.engines is not None:
            d["engines"] = list(self.engines)
        if self.environment is not None:
            d["environment"] = dict(self.environment)
        return d

    @classmethod
    def from_dict(cls, data: Any) -> WorkRequest:
        worker_id = limits.check_id(_field(data, "worker_id", str, "work request"), "work request worker id")
        capacity = _field(data, "capacity", int, "work request")
        if not worker_id or not 1 <= capacity <= _MAX_BATCH:
            raise MessageError("work request is out of range", received=(worker_id, capacity),
                               expected=f"a non-empty worker id and 1 <= capacity <= {_MAX_BATCH}")
        items = _field(data, "results", list, "work request") if "results" in data else []
        if len(items) > _MAX_BATCH:
            raise MessageError("work request carries too many results", received=len(items),
                               expected=f"at most {_MAX_BATCH}")
        return cls(worker_id, capacity, tuple(SubmittedResult.from_dict(i) for i in items),
                   _engines(data.get("engines")), _environment(data.get("environment")))


def _engines(value: Any) -> tuple[str, ...] | None:
    if value is None:
        return None
    if not isinstance(value, list) or len(value) > 16 or not all(
            isinstance(e, str) and e.isidentifier() and len(e) <= 32 for e in value):
        raise MessageError("work request field 'engines' is malformed", received=str(value)[:80],
                           expected="a list of at most 16 engine names")
    return tuple(value)


def _environment(value: Any) -> dict[str, str] | None:
    if value is None:
        return None
    if not isinstance(value, dict) or len(value) > 32 or not all(
            isinstance(k, str) and len(k) <= 32 and isinstance(v, str) for k, v in value.items()):
        raise MessageError("work request field 'environment' is malformed", received=str(value)[:80],
                           expected="at most 32 name: text pairs")
    return {k: limits.check_text(v, f"environment entry {k!r}", 200) for k, v in value.items()}


@dataclass(frozen=True)
class TrialAssignment:
    """One leased trial: run `params_unit` (unit cube of the run's space) with `seed`.

    lease_id identifies this issue of the trial; a result must quote it, so a late result for a
    re-issued trial is recognised and dropped. lease_s: time the coordinator waits for it.
    duration_s: simulated seconds of this evaluation (a multi-fidelity rung); None: the run's duration.
    """

    trial_id: int
    lease_id: int
    params_unit: tuple[float, ...]
    seed: int
    lease_s: float
    duration_s: float | None = None
    fidelity: TaskFidelity | None = None   # a rung's engine / step / settle, or a judge's or audit's task

    def to_dict(self) -> dict[str, Any]:
        d = {"trial_id": self.trial_id, "lease_id": self.lease_id, "params_unit": list(self.params_unit),
             "seed": self.seed, "lease_s": self.lease_s}
        if self.duration_s is not None:
            d["duration_s"] = self.duration_s
        if self.fidelity is not None:
            d["fidelity"] = self.fidelity.to_dict()
        return d

    @classmethod
    def from_dict(cls, data: Any) -> TrialAssignment:
        what = "trial assignment"
        params = _field(data, "params_unit", list, what)
        if not all(isinstance(p, int | float) and not isinstance(p, bool) for p in params):
            raise MessageError("trial assignment has non-numeric parameters", received=params[:8],
                               expected="a list of numbers in [0, 1]")
        duration = None
        if data.get("duration_s") is not None:
            duration = _finite(_field(data, "duration_s", (int, float), what), "duration_s", what)
            if duration <= 0:
                raise MessageError("trial assignment has a non-positive duration", received=duration,
                                   expected="duration_s > 0 s")
        fidelity = None
        if data.get("fidelity") is not None:
            try:
                fidelity = TaskFidelity.from_dict(_field(data, "fidelity", dict, what))
            except ConfigError as exc:
                raise MessageError(f"trial assignment has a bad fidelity: {exc}", received=data["fidelity"],
                                   expected="{task, engine, dt_s, settle_s, perturb}") from exc
        return cls(_field(data, "trial_id", int, what), _field(data, "lease_id", int, what),
                   tuple(float(p) for p in params), _field(data, "seed", int, what),
                   _finite(_field(data, "lease_s", (int, float), what), "lease_s", what), duration, fidelity)


@dataclass(frozen=True)
class WorkGrant:
    """The coordinator's answer to a WorkRequest.

    An empty grant says why: `run_done` (budget met, stop asking) or wait `retry_after_s`.
    """

    KIND = "work_grant"
    run_id: str
    config_hash: str
    assignments: tuple[TrialAssignment, ...]
    retry_after_s: float = 0.0
    run_done: bool = False
    verdicts: tuple[tuple[int, Verdict], ...] = ()   # for the results the request carried

    def to_dict(self) -> dict[str, Any]:
        return {"run_id": self.run_id, "config_hash": self.config_hash,
                "assignments": [a.to_dict() for a in self.assignments],
                "retry_after_s": self.retry_after_s, "run_done": self.run_done,
                "verdicts": ResultAck(self.verdicts).to_dict()["verdicts"]}

    @classmethod
    def from_dict(cls, data: Any) -> WorkGrant:
        what = "work grant"
        items = _field(data, "assignments", list, what)
        verdicts = ResultAck.from_dict({"verdicts": data.get("verdicts", [])}).verdicts
        return cls(_field(data, "run_id", str, what), _field(data, "config_hash", str, what),
                   tuple(TrialAssignment.from_dict(a) for a in items),
                   _finite(_field(data, "retry_after_s", (int, float), what), "retry_after_s", what),
                   _field(data, "run_done", bool, what), verdicts)


@dataclass(frozen=True)
class SubmittedResult:
    """A TrialResult with the lease it answers."""

    lease_id: int
    result: TrialResult

    def to_dict(self) -> dict[str, Any]:
        return {"lease_id": self.lease_id, "result": self.result.to_dict()}

    @classmethod
    def from_dict(cls, data: Any) -> SubmittedResult:
        result = TrialResult.from_dict(_field(data, "result", dict, "submitted result"))
        if result.trial_id < 0:
            raise MessageError("submitted result has no trial id", received=result.trial_id,
                               expected="a trial id >= 0")
        return cls(_field(data, "lease_id", int, "submitted result"), result)


@dataclass(frozen=True)
class ResultSubmission:
    """A worker returns finished trials; it resends them until each is acknowledged."""

    KIND = "result_submission"
    worker_id: str
    items: tuple[SubmittedResult, ...]

    def to_dict(self) -> dict[str, Any]:
        return {"worker_id": self.worker_id, "items": [i.to_dict() for i in self.items]}

    @classmethod
    def from_dict(cls, data: Any) -> ResultSubmission:
        items = _field(data, "items", list, "result submission")
        if len(items) > _MAX_BATCH:
            raise MessageError("result submission is too large", received=len(items),
                               expected=f"at most {_MAX_BATCH} results")
        worker_id = limits.check_id(_field(data, "worker_id", str, "result submission"), "result submission worker id")
        return cls(worker_id,
                   tuple(SubmittedResult.from_dict(i) for i in items))


class Verdict(StrEnum):
    """What the coordinator did with one submitted result. Every verdict is final for the worker."""

    STORED = "stored"          # new, stored now
    DUPLICATE = "duplicate"    # already stored (a resend after a lost ack)
    STALE = "stale"            # the lease expired or the trial was re-issued: dropped
    UNKNOWN = "unknown"        # no such trial in this run: dropped
    INVALID = "invalid"        # the result does not fit the trial (e.g. seed mismatch): dropped
    REQUEUED = "requeued"      # timed out or crashed on its worker: issued again (up to 3 attempts in all)


@dataclass(frozen=True)
class ResultAck:
    KIND = "result_ack"
    verdicts: tuple[tuple[int, Verdict], ...]

    def to_dict(self) -> dict[str, Any]:
        return {"verdicts": [[t, str(v)] for t, v in self.verdicts]}

    @classmethod
    def from_dict(cls, data: Any) -> ResultAck:
        raw = _field(data, "verdicts", list, "result ack")
        try:
            verdicts = tuple((int(t), Verdict(v)) for t, v in raw)
        except (TypeError, ValueError) as exc:
            raise MessageError("result ack has malformed verdicts", received=raw[:4],
                               expected=f"[trial_id, one of {[v.value for v in Verdict]}] pairs") from exc
        return cls(verdicts)


@dataclass(frozen=True)
class RunInfo:
    """A coordinator announces its run so stateless workers can find it."""

    KIND = "run_info"
    run_id: str
    config_hash: str
    trials_budget: int
    run_done: bool

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: Any) -> RunInfo:
        what = "run info"
        return cls(_field(data, "run_id", str, what), _field(data, "config_hash", str, what),
                   _field(data, "trials_budget", int, what), _field(data, "run_done", bool, what))


def encode_message(message: Any) -> bytes:
    """Encode one of the dataclasses above (each has KIND and to_dict)."""
    return encode(message.KIND, message.to_dict())


def decode_message(payload: bytes | str, cls: Any) -> Any:
    """Decode an envelope of `cls.KIND` into `cls`; MessageError for anything else."""
    _, body = decode(payload, cls.KIND)
    try:
        return cls.from_dict(body)
    except MessageError:
        raise
    except (TypeError, ValueError, KeyError, AttributeError, ArithmeticError, RecursionError) as exc:
        raise MessageError(f"{cls.KIND} message is malformed: {exc}", received=str(body)[:120],
                           expected=f"a valid {cls.KIND} body") from exc
