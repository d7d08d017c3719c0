"""The `search:` block of a spec file: the body constants a co-designed search may change, each with its
bounds (docs/morphology-format.md, "Search ranges"). A field is named by its path in the spec file:

    search:
      segments.rod_length_scale: [0.7, 1.3]
      string_materials.outer.stiffness_n_per_m: [700, 1300]

Errors name the file, the line and the field, as everywhere in spec files.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, fields
from typing import Any

from spinefarm.robot.morphology.specyaml import LineDict, SpecSource, line_of, mapping, number
from spinefarm.robot.morphology.structure import RodMaterial, StringMaterial

# which constants of a body may be searched: geometry, strings, motors and mass (through the rods' density).
# The segment count is not among them: every sampler sees a vector of one fixed size.
SEGMENT_FIELDS = ("rod_length_scale", "spacing_scale")
STRING_FIELDS = ("stiffness_n_per_m", "damping_n_s_per_m", "pretension_n", "max_tension_n", "motor_speed_cm_s",
                 "motor_accel_cm_s2")
ROD_FIELDS = ("density_kg_per_cm3",)
SCALE_BOUNDS = (0.0, 100.0, False)  # as specstructure holds segments.*_scale: (0, 100]
UNITS = (("_n_s_per_m", "N s/m"), ("_n_per_m", "N/m"), ("_kg_per_cm3", "kg/cm^3"), ("_cm_s2", "cm/s^2"),
         ("_cm_s", "cm/s"), ("_n", "N"), ("_scale", "1"))


@dataclass(frozen=True)
class BodyField:
    """One searched constant: its path in the spec file, its bounds and where the block names it."""

    path: str
    low: float
    high: float
    line: int | None = None

    @property
    def unit(self) -> str:
        return next(unit for suffix, unit in UNITS if self.path.endswith(suffix))

    @property
    def column(self) -> str:
        """Its name as a stored column: the path with dots as '__' (a dot is no column character)."""
        return "body__" + self.path.replace(".", "__")


def allowed_paths(rod_tags: dict, string_tags: dict) -> list[str]:
    return ([f"segments.{f}" for f in SEGMENT_FIELDS]
            + [f"rod_materials.{t}.{f}" for t in sorted(rod_tags) for f in ROD_FIELDS]
            + [f"string_materials.{t}.{f}" for t in sorted(string_tags) for f in STRING_FIELDS])


def field_bounds(path: str) -> tuple[float | None, float | None, bool]:
    """(low, high, low_inclusive) of a searchable field's valid values, from the spec's own declarations."""
    section, *_, name = path.split(".")
    if section == "segments":
        return SCALE_BOUNDS
    cls = RodMaterial if section == "rod_materials" else StringMaterial
    return next(f.metadata["bounds"] for f in fields(cls) if f.name == name)


def _inside(value: float, bounds: tuple[float | None, float | None, bool]) -> bool:
    low, high, low_inclusive = bounds
    above = low is None or (value >= low if low_inclusive else value > low)
    return above and (high is None or value <= high)


def _range_text(bounds: tuple[float | None, float | None, bool]) -> str:
    low, high, low_inclusive = bounds
    lo = "(-inf" if low is None else f"{'[' if low_inclusive else '('}{low:g}"
    return f"{lo}, {'inf)' if high is None else f'{high:g}]'}"


def parse_search(spec: SpecSource, block: Any, line: int | None, rod_tags: dict,
                 string_tags: dict) -> tuple[BodyField, ...]:
    """The block's fields in the file's order; a one-line error for an unknown field, a malformed or inverted
    range, or a bound outside the field's valid values."""
    block = mapping(spec, block, "search", line)
    if not block:
        raise spec.fail(line, "search", "no fields to search", expected="field: [low, high] lines")
    allowed = allowed_paths(rod_tags, string_tags)
    out = []
    for key, value in block.items():
        kline = line_of(block, key)
        field = f"search.{key}"
        if key not in allowed:
            hint = ("the segment count is fixed: every sampler sees a vector of one size" if key == "segments.count"
                    else "a field of this robot's tags")
            raise spec.fail(kline, field, "unknown field", received=key, expected=f"{hint}; one of {allowed}")
        if not isinstance(value, list) or len(value) != 2:
            raise spec.fail(kline, field, "not a [low, high] pair", received=value, expected="two numbers")
        low, high = (number(spec, v, field, kline) for v in value)
        if not low < high:
            raise spec.fail(kline, field, "empty range", received=[low, high], expected="low < high")
        bounds = field_bounds(key)
        for bound in (low, high):
            if not _inside(bound, bounds):
                raise spec.fail(kline, field, "bound outside the field's valid values", received=bound,
                                expected=f"a value in {_range_text(bounds)}")
        out.append(BodyField(str(key), low, high, kline))
    return tuple(out)


def with_body(doc: LineDict, values: dict[str, float]) -> LineDict:
    """A copy of a spec document with these body constants written in (and no search block)."""
    out = copy.deepcopy(doc)
    out.pop("search", None)
    for path, value in values.items():
        node = out
        *parents, name = path.split(".")
        for key in parents:
            if node.get(key) is None:
                node[key] = LineDict()
                node[key].line, node[key].key_lines = 0, {}
            node = node[key]
        node[name] = float(value)
    return out
