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

from protocol.errors import MessageError

SCHEMA_VERSION = 1


class TrialStatus(StrEnum):
    """waiting -> running -> complete | failed(reason). Finished trials never change."""

    WAITING = "waiting"
    RUNNING = "running"
    COMPLETE = "complete"
    FAILED = "failed"


@dataclass(frozen=True)
class TrialResult:
    """What one trial measured. Distances are in the ground plane; units are in the names.

    distance_m: displacement of the whole robot's centre of mass.
    ntrt_distance_cm: displacement of the segment NTRT scores (spec section 5).
    work_j: work done shortening strings under tension (relaxation is passive).
    cot: work_j / (mass_kg * g * distance_m), dimensionless (inf when distance is 0).
    status: complete, or failed with `reason` (diverged: ..., error: ...); partial metrics kept.
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

    @property
    def ok(self) -> bool:
        return self.status == TrialStatus.COMPLETE

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["status"] = str(self.status)
        return d

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TrialResult:
        if not isinstance(data, dict):
            raise MessageError("trial result is not an object", received=type(data).__name__,
                               expected="a JSON object")
        kwargs: dict[str, Any] = {}
        for f in fields(cls):
            if f.name not in data:
                if f.name in ("trial_id", "worker_id", "extras"):
                    continue
                raise MessageError(f"trial result lacks field {f.name!r}", received=sorted(data),
                                   expected=[g.name for g in fields(cls)])
            kwargs[f.name] = data[f.name]
        try:
            kwargs["status"] = TrialStatus(kwargs["status"])
        except ValueError as exc:
            raise MessageError("trial result has an unknown status", received=kwargs["status"],
                               expected=[s.value for s in TrialStatus]) from exc
        for name in ("distance_m", "ntrt_distance_cm", "speed_cm_s", "work_j", "cot", "sim_time_s",
                     "wall_time_s", "mass_kg"):
            v = kwargs[name]
            if isinstance(v, bool) or not isinstance(v, int | float):
                raise MessageError(f"trial result field {name!r} is not a number", received=v,
                                   expected="a number")
            kwargs[name] = float(v)
        for name in ("seed", "trial_id"):
            if name in kwargs and (isinstance(kwargs[name], bool) or not isinstance(kwargs[name], int)):
                raise MessageError(f"trial result field {name!r} is not an integer", received=kwargs[name],
                                   expected="an integer")
        if not isinstance(kwargs["reason"], str):
            raise MessageError("trial result field 'reason' is not a string", received=kwargs["reason"],
                               expected="a string")
        return cls(**kwargs)


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
    try:
        envelope = json.loads(payload)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        shown = payload[:60] if isinstance(payload, bytes | str) else type(payload).__name__
        raise MessageError("message is not JSON", received=shown,
                           expected="a JSON envelope {schema, kind, body}") from exc
    if not isinstance(envelope, dict) or not {"schema", "kind", "body"} <= set(envelope):
        got = sorted(envelope) if isinstance(envelope, dict) else type(envelope).__name__
        raise MessageError("message is not a spinefarm envelope", received=got,
                           expected="an object with keys schema, kind, body")
    if envelope["schema"] != SCHEMA_VERSION:
        raise MessageError("message has another schema version", received=envelope["schema"],
                           expected=SCHEMA_VERSION)
    kind = envelope["kind"]
    if expected_kind is not None and kind != expected_kind:
        raise MessageError("message is of another kind", received=kind, expected=expected_kind)
    if not isinstance(envelope["body"], dict):
        raise MessageError("message body is not an object", received=type(envelope["body"]).__name__,
                           expected="a JSON object")
    return kind, _restore_floats(envelope["body"])
