"""The envelope every message travels in: JSON with a schema version, and the field checks decoders share.

Every decoded message is validated: a wrong schema version, a missing field or a field of
the wrong kind raises MessageError naming what was received and what was expected.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, fields
from typing import Any, ClassVar

from spinefarm.protocol import limits
from spinefarm.protocol.errors import MessageError

SCHEMA_VERSION = 1


def json_default(obj: Any) -> Any:
    import numpy as np

    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"cannot encode {type(obj).__name__}")


def finite_or_str(x: Any) -> Any:
    # JSON has no inf/nan: encode them as strings so every peer can parse the message.
    if isinstance(x, float) and not math.isfinite(x):
        return repr(x)
    if isinstance(x, dict):
        return {k: finite_or_str(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [finite_or_str(v) for v in x]
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
    envelope = {"schema": SCHEMA_VERSION, "kind": kind, "body": finite_or_str(body)}
    return json.dumps(envelope, default=json_default, separators=(",", ":")).encode()


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

def get_field(data: Any, name: str, kinds: type | tuple[type, ...], what: str) -> Any:
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


def finite(value: float, name: str, what: str) -> float:
    if not math.isfinite(value):
        raise MessageError(f"{what} field {name!r} is not finite", received=value, expected="a finite number")
    return float(value)


def encode_message(message: Any) -> bytes:
    """Encode a message dataclass (each has KIND and to_dict)."""
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


_FLAT_KINDS: dict[str, type | tuple[type, ...]] = {"str": str, "int": int, "bool": bool, "float": (int, float)}


class FlatMessage:
    """A message dataclass whose fields are str, int, bool or float (annotated so): `to_dict` gives them,
    `from_dict` checks each against its annotation (a float must be finite), naming the message (WHAT)."""

    KIND: ClassVar[str]
    WHAT: ClassVar[str]

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)  # type: ignore[call-overload]  # every subclass is a dataclass

    @classmethod
    def from_dict(cls, data: Any) -> Any:
        values = {}
        for f in fields(cls):  # type: ignore[arg-type]
            value = get_field(data, f.name, _FLAT_KINDS[str(f.type)], cls.WHAT)
            values[f.name] = finite(value, f.name, cls.WHAT) if f.type == "float" else value
        return cls(**values)
