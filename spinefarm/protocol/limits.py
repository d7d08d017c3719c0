"""Bounds on what a peer may send: size, nesting, integer digits, finite numbers, id and text lengths.

Anyone who reaches the Zenoh endpoint can send bytes; parsing them must cost bounded time and memory
and end in a MessageError (answered with an error reply), never in an uncaught RecursionError,
ValueError from a 5,000-digit integer, or an infinity made of 1e400.
"""

from __future__ import annotations

import json
import math
import re
from typing import Any

from spinefarm.protocol.errors import MessageError

MAX_MESSAGE_BYTES = 4 * 1024 * 1024   # a run config with a large spec, or 4096 results, fits
MAX_DEPTH = 32                       # run configs nest spec -> structure -> tags -> ...: about 8
MAX_INT_DIGITS = 20                  # int64 and a sign
MAX_TEXT_CHARS = 1000                # a failure reason
MAX_EXTRAS = 16
MAX_BATCH = 4096                     # trials granted or results carried in one message
ID_PATTERN = re.compile(r"^[A-Za-z0-9_.\-]{1,64}$")  # run and worker ids: one Zenoh key chunk


def _parse_int(text: str) -> int:
    if len(text.lstrip("-")) > MAX_INT_DIGITS:
        raise MessageError("message has an integer that is too long", received=f"{len(text)} digits",
                           expected=f"at most {MAX_INT_DIGITS} digits")
    return int(text)


def _parse_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):  # 1e400 parses as inf
        raise MessageError("message has a number out of range", received=text[:40],
                           expected="a finite double (non-finite values travel as the strings inf, -inf, nan)")
    return value


def _reject_constant(text: str) -> float:
    raise MessageError("message has a non-JSON constant", received=text, expected="standard JSON numbers")


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """An object whose keys are all distinct (JSON parsers disagree on which duplicate wins)."""
    out = dict(pairs)
    if len(out) != len(pairs):
        seen: set[str] = set()
        dup = next(k for k, _ in pairs if k in seen or seen.add(k))
        raise MessageError("message has a duplicate key", received=dup[:60], expected="distinct keys per object")
    return out


def _too_deep(value: Any) -> bool:
    stack = [(value, 1)]
    while stack:
        v, depth = stack.pop()
        if isinstance(v, dict | list):
            if depth > MAX_DEPTH:
                return True
            stack.extend((c, depth + 1) for c in (v.values() if isinstance(v, dict) else v))
    return False


def loads(payload: bytes | str) -> Any:
    """json.loads within the limits above; MessageError for anything else."""
    if not isinstance(payload, bytes | bytearray | str):
        raise MessageError("message is not bytes", received=type(payload).__name__, expected="UTF-8 JSON bytes")
    if len(payload) > MAX_MESSAGE_BYTES:
        raise MessageError("message is too large", received=f"{len(payload)} bytes",
                           expected=f"at most {MAX_MESSAGE_BYTES} bytes")
    try:
        value = json.loads(payload, parse_int=_parse_int, parse_float=_parse_float, parse_constant=_reject_constant,
                           object_pairs_hook=_no_duplicates)
    except MessageError:
        raise
    except RecursionError:
        raise MessageError("message is nested too deeply", expected=f"at most {MAX_DEPTH} levels") from None
    except (UnicodeDecodeError, ValueError) as exc:  # JSONDecodeError is a ValueError
        raise MessageError("message is not JSON", received=bytes(payload[:60]) if not isinstance(payload, str)
                           else payload[:60], expected="a JSON envelope {schema, kind, body}") from exc
    if _too_deep(value):
        raise MessageError("message is nested too deeply", expected=f"at most {MAX_DEPTH} levels")
    return value


def check_id(value: Any, what: str) -> str:
    """A run or worker id as peers may send it: 1-64 characters from A-Z a-z 0-9 _ . -"""
    if not isinstance(value, str) or not ID_PATTERN.match(value):
        shown = value[:70] if isinstance(value, str) else type(value).__name__
        raise MessageError(f"{what} is not a valid id", received=shown,
                           expected="1-64 characters from A-Z a-z 0-9 _ . -")
    return value


def check_text(value: Any, what: str, max_chars: int = MAX_TEXT_CHARS) -> str:
    if not isinstance(value, str) or len(value) > max_chars:
        shown = f"{len(value)} characters" if isinstance(value, str) else type(value).__name__
        raise MessageError(f"{what} is too long or not text", received=shown,
                           expected=f"a string of at most {max_chars} characters")
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:  # lone surrogates (\ud800) cannot be stored or served
        raise MessageError(f"{what} is not valid Unicode", received=repr(value[:40]),
                           expected="text without lone surrogates") from None
    return value
