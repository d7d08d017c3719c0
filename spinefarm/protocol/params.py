"""Named, bounded, unit-carrying parameter spaces and their unit-cube mapping.

Samplers work in the unit cube [0, 1]^n; trials run on physical values. A ParamSpace
maps between them and validates vectors with errors that say what was expected.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from spinefarm.protocol.errors import ParameterError


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: physical value = low + u * (high - low) for u in [0, 1]."""

    name: str
    low: float
    high: float
    unit: str = ""
    doc: str = ""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.low) and math.isfinite(self.high)) or self.high < self.low:
            raise ParameterError(f"bounds of parameter {self.name!r} are invalid",
                                 received=(self.low, self.high), expected="finite low <= high")


@dataclass(frozen=True)
class ParamSpace:
    """An ordered tuple of ParamSpecs with a stable hash."""

    name: str
    specs: tuple[ParamSpec, ...]

    def __post_init__(self) -> None:
        names = [s.name for s in self.specs]
        if len(set(names)) != len(names):
            dup = sorted({n for n in names if names.count(n) > 1})
            raise ParameterError(f"space {self.name!r} has duplicate parameter names", received=dup)

    def __len__(self) -> int:
        return len(self.specs)

    @property
    def names(self) -> list[str]:
        return [s.name for s in self.specs]

    @property
    def lows(self) -> np.ndarray:
        return np.array([s.low for s in self.specs], dtype=float)

    @property
    def highs(self) -> np.ndarray:
        return np.array([s.high for s in self.specs], dtype=float)

    @property
    def units(self) -> list[str]:
        return [s.unit for s in self.specs]

    def _check_vector(self, vector: Sequence[float] | np.ndarray, what: str) -> np.ndarray:
        try:
            arr = np.asarray(vector, dtype=float)
        except (TypeError, ValueError) as exc:
            raise ParameterError(f"{what} for space {self.name!r} is not numeric",
                                 received=type(vector).__name__, expected=f"{len(self)} numbers") from exc
        if arr.ndim != 1 or arr.shape[0] != len(self):
            raise ParameterError(f"{what} for space {self.name!r} has the wrong length",
                                 received=f"shape {arr.shape}", expected=f"{len(self)} values ({self.name})")
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            i = int(bad[0])
            raise ParameterError(f"{what} for space {self.name!r} has a non-finite value at "
                                 f"index {i} ({self.specs[i].name})", received=float(arr[i]),
                                 expected="finite numbers")
        return arr

    def check_unit(self, unit_vector: Sequence[float] | np.ndarray) -> np.ndarray:
        """Validate a unit-cube vector (length, finiteness, 0 <= u <= 1)."""
        arr = self._check_vector(unit_vector, "unit-cube vector")
        out = np.flatnonzero((arr < 0.0) | (arr > 1.0))
        if out.size:
            i = int(out[0])
            raise ParameterError(f"unit-cube value {self.specs[i].name!r} (index {i}) is outside [0, 1]",
                                 received=float(arr[i]), expected="0 <= u <= 1")
        return arr

    def from_unit(self, unit_vector: Sequence[float] | np.ndarray) -> np.ndarray:
        """Physical values of a unit-cube vector."""
        u = self.check_unit(unit_vector)
        return self.lows + u * (self.highs - self.lows)

    def physical(self, params: Sequence[float] | np.ndarray | Mapping[str, float]) -> np.ndarray:
        """Physical values of a unit-cube vector, or of a mapping of named physical values (bounds checked)."""
        if isinstance(params, Mapping):
            physical = self.from_named(params)
            self.to_unit(physical)  # bounds check with a named error
            return physical
        return self.from_unit(params)

    def to_unit(self, physical: Sequence[float] | np.ndarray) -> np.ndarray:
        """Unit-cube coordinates of physical values (a zero-width parameter maps to 0)."""
        x = self._check_vector(physical, "physical vector")
        width = self.highs - self.lows
        safe = np.where(width > 0, width, 1.0)
        u = np.where(width > 0, (x - self.lows) / safe, 0.0)
        out = np.flatnonzero((u < -1e-9) | (u > 1 + 1e-9))
        if out.size:
            i = int(out[0])
            s = self.specs[i]
            raise ParameterError(f"value of {s.name!r} is outside its bounds", received=float(x[i]),
                                 expected=f"{s.low:g} <= value <= {s.high:g} {s.unit}".rstrip())
        return np.clip(u, 0.0, 1.0)

    def from_named(self, values: Mapping[str, float]) -> np.ndarray:
        """Physical vector from a name -> value mapping holding exactly this space's names."""
        missing = [n for n in self.names if n not in values]
        unknown = sorted(set(values) - set(self.names))
        if missing or unknown:
            raise ParameterError(
                f"named parameters do not match space {self.name!r}",
                received=f"{len(values)} names (missing {missing[:5]}{'...' if len(missing) > 5 else ''}, "
                         f"unknown {unknown[:5]}{'...' if len(unknown) > 5 else ''})",
                expected=f"exactly the {len(self)} names of the space")
        return self._check_vector([values[n] for n in self.names], "named parameters")

    def to_named(self, physical: Iterable[float]) -> dict[str, float]:
        x = self._check_vector(list(physical), "physical vector")
        return {n: float(v) for n, v in zip(self.names, x, strict=True)}

    def describe(self) -> list[dict[str, object]]:
        """JSON-ready description (name, low, high, unit, doc) of every parameter."""
        return [{"name": s.name, "low": s.low, "high": s.high, "unit": s.unit, "doc": s.doc} for s in self.specs]

    def space_hash(self) -> str:
        """Hex digest identifying names, bounds and units (not docs)."""
        blob = json.dumps([self.name, [[s.name, s.low, s.high, s.unit] for s in self.specs]], sort_keys=True)
        return hashlib.sha256(blob.encode()).hexdigest()[:16]
