"""One root error class; every message says what was received and what was expected."""

from __future__ import annotations

import dataclasses
import math
from typing import Any


class SpinefarmError(Exception):
    """Root of every error spinefarm raises on purpose.

    `code` is a stable machine-readable identifier (used in HTTP error details);
    the message names what was received and what was expected.
    """

    code = "spinefarm_error"

    def __init__(self, message: str, *, received: Any = None, expected: Any = None) -> None:
        self.received = received
        self.expected = expected
        parts = [message]
        if received is not None:
            parts.append(f"received {received!r}")
        if expected is not None:
            parts.append(f"expected {expected}")
        super().__init__("; ".join(parts))

    def to_detail(self) -> dict[str, Any]:
        return {"code": self.code, "message": str(self)}


class ConfigError(SpinefarmError, ValueError):
    """A configuration value is out of range or of the wrong kind."""

    code = "invalid_config"


class ParameterError(SpinefarmError, ValueError):
    """A parameter vector has the wrong length, a non-finite value or an unknown name."""

    code = "invalid_parameters"


class UnknownMorphologyError(SpinefarmError, KeyError):
    """A morphology name is not registered and is not a readable spec file."""

    code = "unknown_morphology"

    def __str__(self) -> str:  # KeyError would quote the message
        return Exception.__str__(self)


class MorphologySpecError(SpinefarmError, ValueError):
    """A structure file is malformed; the message names the field (and line when known)."""

    code = "invalid_morphology_spec"


class MessageError(SpinefarmError, ValueError):
    """A transport message is malformed, foreign or of another schema version."""

    code = "malformed_message"


class StorageError(SpinefarmError):
    """The results store cannot be opened or does not hold what was asked for."""

    code = "storage_error"


def check_range(field: str, value: float, low: float | None = None, high: float | None = None,
                *, low_inclusive: bool = True) -> None:
    """Raise ConfigError naming `field` unless low <= value <= high (and finite)."""
    ok = isinstance(value, int | float) and math.isfinite(value)
    if ok and low is not None:
        ok = value >= low if low_inclusive else value > low
    if ok and high is not None:
        ok = value <= high
    if not ok:
        lo = "-inf" if low is None else f"{low:g}"
        hi = "inf" if high is None else f"{high:g}"
        bracket = "[" if low_inclusive else "("
        raise ConfigError(f"{field} out of range", received=value, expected=f"a finite number in {bracket}{lo}, {hi}]")


def bounded(default: Any = dataclasses.MISSING, low: float | None = None, high: float | None = None, *,
            low_inclusive: bool = True) -> Any:
    """A dataclass field with its range declared beside it; check_fields holds every such field to it
    (a None value is an unset option and is not checked)."""
    return dataclasses.field(default=default, metadata={"bounds": (low, high, low_inclusive)})


def whole(default: int, low: int, high: int) -> Any:
    """A dataclass field holding an integer in [low, high] (a bool is no integer here)."""
    return dataclasses.field(default=default, metadata={"whole": (low, high)})


def check_fields(record: Any, prefix: str = "") -> None:
    """Hold each bounded and whole field of a dataclass to its range, in declaration order; errors
    name prefix + the field's name."""
    for f in dataclasses.fields(record):
        value = getattr(record, f.name)
        if "bounds" in f.metadata and value is not None:
            low, high, low_inclusive = f.metadata["bounds"]
            check_range(prefix + f.name, value, low, high, low_inclusive=low_inclusive)
        elif "whole" in f.metadata:
            low, high = f.metadata["whole"]
            if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
                raise ConfigError(f"{prefix}{f.name} out of range", received=value,
                                  expected=f"an integer in [{low}, {high}]")


class RunMismatchError(ConfigError):
    """A worker cannot build the run it was handed as the coordinator defined it."""
