"""Reading spec-file YAML with line numbers: containers that remember where they came from, numbers
that may be arithmetic expressions, and errors that name the file, line and field."""

from __future__ import annotations

import re
from typing import Any

import numpy as np
import yaml

from spinefarm.protocol.errors import MorphologySpecError
from spinefarm.robot.morphology.specexpr import ExpressionError, evaluate

WHEN = ("all", "even", "odd")


class LineDict(dict):
    """A YAML mapping that remembers its own line and each key's line (1-based)."""

    line: int = 0
    key_lines: dict


class LineList(list):
    """A YAML sequence that remembers its own line and each item's line (1-based)."""

    line: int = 0
    item_lines: list


class SpecSource:
    """Error reporting bound to one source (a file name or '<string>')."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, line: int | None, field: str, message: str, received: Any = None,
             expected: Any = None) -> MorphologySpecError:
        where = f"{self.source}, line {line}" if line else self.source
        return MorphologySpecError(f"{where}, field {field}: {message}", received=received, expected=expected)


def compose(text: str, spec: SpecSource) -> Any:
    loader = yaml.SafeLoader(text)
    try:
        root = loader.get_single_node()
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        raise spec.fail(mark.line + 1 if mark else None, "(document)", "not valid YAML",
                        received=str(getattr(exc, "problem", exc)), expected="a YAML mapping") from exc
    finally:
        loader.dispose()
    if root is None:
        raise spec.fail(None, "(document)", "the file is empty", expected="a YAML mapping")
    constructor = yaml.SafeLoader("")

    def conv(node: yaml.Node) -> Any:
        if isinstance(node, yaml.MappingNode):
            out = LineDict()
            out.line = node.start_mark.line + 1
            out.key_lines = {}
            for k_node, v_node in node.value:
                key = conv(k_node)
                if key in out:
                    raise spec.fail(k_node.start_mark.line + 1, str(key), "duplicate key",
                                    received=key, expected="each key once per mapping")
                out[key] = conv(v_node)
                out.key_lines[key] = k_node.start_mark.line + 1
            return out
        if isinstance(node, yaml.SequenceNode):
            seq = LineList(conv(v) for v in node.value)
            seq.line = node.start_mark.line + 1
            seq.item_lines = [v.start_mark.line + 1 for v in node.value]
            return seq
        return constructor.construct_object(node)

    return conv(root)


def line_of(container: Any, key: Any = None) -> int | None:
    if isinstance(container, LineDict):
        return container.key_lines.get(key, container.line) if key is not None else container.line
    if isinstance(container, LineList):
        if isinstance(key, int) and 0 <= key < len(container.item_lines):
            return container.item_lines[key]
        return container.line
    return None


def number(spec: SpecSource, value: Any, field: str, line: int | None,
            names: dict[str, float] | None = None) -> float:
    if isinstance(value, bool):
        raise spec.fail(line, field, "not a number", received=value, expected="a number or an expression")
    if isinstance(value, int | float):
        return float(value)
    if isinstance(value, str):
        try:
            return float(evaluate(value, names or {}))
        except ExpressionError as exc:
            raise spec.fail(line, field, str(exc), received=value,
                            expected="a number or an arithmetic expression") from exc
    raise spec.fail(line, field, "not a number", received=value, expected="a number or an expression")


def vector(spec: SpecSource, value: Any, field: str, line: int | None, names: dict[str, float] | None = None
            ) -> np.ndarray:
    if not isinstance(value, list) or len(value) != 3:
        raise spec.fail(line_of(value) or line, field, "not an (x, y, z) triple", received=value,
                        expected="a list of 3 numbers (cm)")
    return np.array([number(spec, v, f"{field}[{c}]", line_of(value, c) or line, names)
                     for c, v in enumerate(value)])


def mapping(spec: SpecSource, value: Any, field: str, line: int | None, allowed: tuple[str, ...] | None = None,
             required: tuple[str, ...] = ()) -> LineDict:
    if not isinstance(value, dict):
        raise spec.fail(line, field, "not a mapping", received=value, expected="a mapping of keys to values")
    if allowed is not None:
        unknown = [k for k in value if k not in allowed]
        if unknown:
            raise spec.fail(line_of(value, unknown[0]), f"{field}.{unknown[0]}", "unknown key",
                            received=unknown[0], expected=f"one of {list(allowed)}")
    for key in required:
        if key not in value:
            raise spec.fail(line_of(value), field, f"missing key {key!r}", expected=f"keys {list(required)}")
    return value  # type: ignore[return-value]


def applies(spec: SpecSource, when: Any, index: int, field: str, line: int | None) -> bool:
    if when not in WHEN:
        raise spec.fail(line, field, "unknown selector", received=when, expected=f"one of {list(WHEN)}")
    return when == "all" or (index % 2 == 0) == (when == "even")


def format_name(spec: SpecSource, template: str, k: int, field: str, line: int | None) -> str:
    def sub(m: re.Match) -> str:
        try:
            return str(int(evaluate(m.group(1), {"k": k})))
        except ExpressionError as exc:
            raise spec.fail(line, field, str(exc), received=template,
                            expected="{k} or {k + 1} style") from exc

    return re.sub(r"\{([^{}]*)\}", sub, template)
