"""Morphology spec files (YAML): a segment template repeated N times, joint string templates, materials
and controller defaults. The format is documented in docs/morphology-format.md.

Every error names the file, the line and the field, what was found and what was expected. Lines come
from PyYAML's node marks, kept on the LineDict/LineList containers built here.
"""

from __future__ import annotations

import re
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from protocol.errors import ConfigError, MorphologySpecError
from worker.morphology.model import ControlSpec, ImpedanceGains, Morphology
from worker.morphology.specexpr import ExpressionError, evaluate
from worker.morphology.structure import (
    Rod,
    RodMaterial,
    String,
    StringMaterial,
    StructureSpec,
    rotation_matrix,
)

SPEC_DIR = Path(__file__).parent / "specs"
TOP_KEYS = ("name", "description", "segments", "placement", "joints", "rod_materials", "string_materials",
            "control", "scored_segment", "duration_s", "ground_friction", "controllers", "extra")
WHEN = ("all", "even", "odd")


class LineDict(dict):
    """A YAML mapping that remembers its own line and each key's line (1-based)."""

    line: int = 0
    key_lines: dict


class LineList(list):
    """A YAML sequence that remembers its own line and each item's line (1-based)."""

    line: int = 0
    item_lines: list


class _Spec:
    """Error reporting bound to one source (a file name or '<string>')."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, line: int | None, field: str, message: str, received: Any = None,
             expected: Any = None) -> MorphologySpecError:
        where = f"{self.source}, line {line}" if line else self.source
        return MorphologySpecError(f"{where}, field {field}: {message}", received=received, expected=expected)


def _compose(text: str, spec: _Spec) -> Any:
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


def _line(container: Any, key: Any = None) -> int | None:
    if isinstance(container, LineDict):
        return container.key_lines.get(key, container.line) if key is not None else container.line
    if isinstance(container, LineList):
        if isinstance(key, int) and 0 <= key < len(container.item_lines):
            return container.item_lines[key]
        return container.line
    return None


def _number(spec: _Spec, value: Any, field: str, line: int | None,
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


def _vector(spec: _Spec, value: Any, field: str, line: int | None, names: dict[str, float] | None = None
            ) -> np.ndarray:
    if not isinstance(value, list) or len(value) != 3:
        raise spec.fail(_line(value) or line, field, "not an (x, y, z) triple", received=value,
                        expected="a list of 3 numbers (cm)")
    return np.array([_number(spec, v, f"{field}[{c}]", _line(value, c) or line, names)
                     for c, v in enumerate(value)])


def _mapping(spec: _Spec, value: Any, field: str, line: int | None, allowed: tuple[str, ...] | None = None,
             required: tuple[str, ...] = ()) -> LineDict:
    if not isinstance(value, dict):
        raise spec.fail(line, field, "not a mapping", received=value, expected="a mapping of keys to values")
    if allowed is not None:
        unknown = [k for k in value if k not in allowed]
        if unknown:
            raise spec.fail(_line(value, unknown[0]), f"{field}.{unknown[0]}", "unknown key",
                            received=unknown[0], expected=f"one of {list(allowed)}")
    for key in required:
        if key not in value:
            raise spec.fail(_line(value), field, f"missing key {key!r}", expected=f"keys {list(required)}")
    return value  # type: ignore[return-value]


def _applies(spec: _Spec, when: Any, index: int, field: str, line: int | None) -> bool:
    if when not in WHEN:
        raise spec.fail(line, field, "unknown selector", received=when, expected=f"one of {list(WHEN)}")
    return when == "all" or (index % 2 == 0) == (when == "even")


def _format_name(spec: _Spec, template: str, k: int, field: str, line: int | None) -> str:
    def sub(m: re.Match) -> str:
        try:
            return str(int(evaluate(m.group(1), {"k": k})))
        except ExpressionError as exc:
            raise spec.fail(line, field, str(exc), received=template,
                            expected="{k} or {k + 1} style") from exc

    return re.sub(r"\{([^{}]*)\}", sub, template)


# -- segment template ----------------------------------------------------------------------------
def _template_nodes(spec: _Spec, nodes: Any, line: int | None) -> tuple[list[str], list[np.ndarray]]:
    nodes = _mapping(spec, nodes, "segments.nodes", line)
    names: list[str] = []
    points: list[np.ndarray] = []
    for key, value in nodes.items():
        kline = _line(nodes, key)
        field = f"segments.nodes.{key}"
        if isinstance(value, dict):
            series = _mapping(spec, value, field, kline, allowed=("count", "at"), required=("count", "at"))
            count = series["count"]
            if not isinstance(count, int) or count < 1:
                raise spec.fail(_line(series, "count"), f"{field}.count", "not a positive integer",
                                received=count, expected="an integer >= 1")
            if "{" not in str(key):
                raise spec.fail(kline, field, "a node series needs {k} in its name", received=key,
                                expected="a name like 'rib_{k}'")
            for k in range(count):
                names.append(_format_name(spec, str(key), k, field, kline))
                points.append(_vector(spec, series["at"], f"{field}.at", _line(series, "at"), {"k": k}))
        else:
            names.append(str(key))
            points.append(_vector(spec, value, field, kline))
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise spec.fail(line, "segments.nodes", "node names repeat", received=dup, expected="unique names")
    return names, points


def _template_rods(spec: _Spec, rods: Any, names: list[str], points: list[np.ndarray], rod_tags: dict,
                   line: int | None) -> list[tuple[int, int, str]]:
    if not isinstance(rods, list) or not rods:
        raise spec.fail(line, "segments.rods", "no rods", received=rods, expected="a non-empty list")
    index = {n: i for i, n in enumerate(names)}
    out = []
    for r, entry in enumerate(rods):
        rline = _line(rods, r)
        field = f"segments.rods[{r}]"
        if isinstance(entry, list):
            if len(entry) != 3:
                raise spec.fail(rline, field, "not [from, to, tag]", received=entry, expected="3 items")
            ends, tag, count = (entry[0], entry[1]), entry[2], None
        else:
            m = _mapping(spec, entry, field, rline, allowed=("from", "to", "tag", "count"),
                         required=("from", "to", "tag"))
            ends, tag, count = (m["from"], m["to"]), m["tag"], m.get("count")
        if count is not None and (not isinstance(count, int) or count < 1):
            raise spec.fail(rline, f"{field}.count", "not a positive integer", received=count,
                            expected="an integer >= 1")
        for k in range(count or 1):
            pair = [_format_name(spec, str(e), k, field, rline) if count else str(e) for e in ends]
            for name in pair:
                if name not in index:
                    raise spec.fail(rline, field, "unknown node", received=name,
                                    expected=f"a node of segments.nodes: {names}")
            a, b = index[pair[0]], index[pair[1]]
            if np.linalg.norm(points[a] - points[b]) < 1e-9:
                raise spec.fail(rline, field, "rod of zero length", received=f"{pair[0]} -> {pair[1]}",
                                expected="two nodes at different points (length > 0 cm)")
            if str(tag) not in rod_tags:
                raise spec.fail(rline, f"{field}.tag", "no rod config for this tag", received=tag,
                                expected=f"a tag of rod_materials: {sorted(rod_tags)}")
            out.append((a, b, str(tag)))
    return out


def _transform(spec: _Spec, steps: Any, field: str, line: int | None, index: int | None,
               names: dict[str, float], pts: np.ndarray) -> np.ndarray:
    """Apply a list of {translate | rotate, when} steps to pts (n, 3) cm."""
    if steps is None:
        return pts
    if not isinstance(steps, list):
        raise spec.fail(line, field, "not a list of transforms", received=steps,
                        expected="a list of {translate: [x, y, z]} or {rotate: {axis, degrees}}")
    for t, step in enumerate(steps):
        tline = _line(steps, t)
        tfield = f"{field}[{t}]"
        m = _mapping(spec, step, tfield, tline, allowed=("translate", "rotate", "when"))
        kinds = [k for k in ("translate", "rotate") if k in m]
        if len(kinds) != 1:
            raise spec.fail(tline, tfield, "needs exactly one of translate or rotate", received=sorted(m),
                            expected="translate or rotate (and optionally when)")
        if index is not None and not _applies(spec, m.get("when", "all"), index, f"{tfield}.when",
                                              _line(m, "when")):
            continue
        if index is None and "when" in m:
            raise spec.fail(tline, f"{tfield}.when", "placement applies to every node", received=m["when"],
                            expected="no 'when' in placement")
        if "translate" in m:
            pts = pts + _vector(spec, m["translate"], f"{tfield}.translate", _line(m, "translate"), names)
        else:
            rot = _mapping(spec, m["rotate"], f"{tfield}.rotate", _line(m, "rotate"),
                           allowed=("axis", "degrees", "about"), required=("axis", "degrees"))
            rline = _line(rot)
            axis = _vector(spec, rot["axis"], f"{tfield}.rotate.axis", rline, names)
            if np.linalg.norm(axis) == 0.0:
                raise spec.fail(rline, f"{tfield}.rotate.axis", "zero axis", received=list(axis),
                                expected="a non-zero direction")
            angle = np.radians(_number(spec, rot["degrees"], f"{tfield}.rotate.degrees", rline, names))
            r = rotation_matrix(tuple(axis), float(angle))
            if "about" in rot:
                about = _vector(spec, rot["about"], f"{tfield}.rotate.about", rline, names)
                pts = (pts - about) @ r.T + about
            else:
                pts = pts @ r.T
    return pts


# -- joints --------------------------------------------------------------------------------------
def _joint_strings(spec: _Spec, joints: Any, names: list[str], n_segments: int, string_tags: dict,
                   cpg_tags: tuple[str, ...], line: int | None) -> list[String]:
    """Strings of every joint. Passive (non-CPG) strings come first, as NTRT creates them; within each
    group joint by joint, and within a joint in the order the blocks list them."""
    if not isinstance(joints, list) or not joints:
        raise spec.fail(line, "joints", "no joint strings", received=joints, expected="a non-empty list")
    index = {n: i for i, n in enumerate(names)}
    per = len(names)
    blocks = []
    for j, block in enumerate(joints):
        jline = _line(joints, j)
        field = f"joints[{j}]"
        m = _mapping(spec, block, field, jline, allowed=("tag", "strings", "when", "span"),
                     required=("tag", "strings"))
        tag = str(m["tag"])
        if tag not in string_tags:
            raise spec.fail(_line(m, "tag"), f"{field}.tag", "no string config for this tag", received=tag,
                            expected=f"a tag of string_materials: {sorted(string_tags)}")
        span = m.get("span", 1)
        if not isinstance(span, int) or isinstance(span, bool):
            raise spec.fail(_line(m, "span"), f"{field}.span", "not an integer", received=span,
                            expected="segments between the two ends (>= 1)")
        if span == 0:
            raise spec.fail(_line(m, "span"), f"{field}.span", "string joining a body to itself",
                            received=span, expected="span >= 1 (ends on two different segments)")
        if not 1 <= span < n_segments:
            raise spec.fail(_line(m, "span"), f"{field}.span", "span out of range", received=span,
                            expected=f"an integer in [1, {n_segments - 1}]")
        pairs = m["strings"]
        if not isinstance(pairs, list) or not pairs:
            raise spec.fail(_line(m, "strings"), f"{field}.strings", "no strings", received=pairs,
                            expected="a list of [node on segment s, node on segment s + span]")
        resolved = []
        for p, pair in enumerate(pairs):
            pline = _line(pairs, p)
            if not isinstance(pair, list) or len(pair) != 2:
                raise spec.fail(pline, f"{field}.strings[{p}]", "not a [from, to] pair", received=pair,
                                expected="two node names")
            for name in pair:
                if str(name) not in index:
                    raise spec.fail(pline, f"{field}.strings[{p}]", "unknown node", received=name,
                                    expected=f"a node of segments.nodes: {names}")
            resolved.append((index[str(pair[0])], index[str(pair[1])]))
        _applies(spec, m.get("when", "all"), 0, f"{field}.when", _line(m, "when"))
        blocks.append((tag, span, m.get("when", "all"), resolved, jline))
    out: list[String] = []
    for cpg_group in (False, True):
        for s in range(n_segments - 1):
            for tag, span, when, resolved, jline in blocks:
                if (tag in cpg_tags) != cpg_group or s + span >= n_segments:
                    continue
                if _applies(spec, when, s, "joints.when", jline):
                    out.extend(String(s * per + a, (s + span) * per + b, tag) for a, b in resolved)
    return out


# -- materials and control -----------------------------------------------------------------------
def _materials(spec: _Spec, section: Any, name: str, cls: type, line: int | None) -> dict:
    section = _mapping(spec, section, name, line)
    if not section:
        raise spec.fail(line, name, "no materials", expected="at least one tag")
    allowed = tuple(f.name for f in fields(cls))
    out = {}
    for tag, value in section.items():
        field = f"{name}.{tag}"
        m = _mapping(spec, value if value is not None else LineDict(), field, _line(section, tag),
                     allowed=allowed)
        kwargs = {k: (None if v is None else _number(spec, v, f"{field}.{k}", _line(m, k)))
                  for k, v in m.items()}
        try:
            out[str(tag)] = cls(**kwargs)
        except ConfigError as exc:
            raise spec.fail(_line(section, tag), field, str(exc),
                            expected=f"valid {cls.__name__} fields") from exc
    return out


def _control(spec: _Spec, section: Any, line: int | None, string_tags: dict) -> ControlSpec:
    allowed = ("cpg_tags", "impedance", "cpg_update_period_s", "node_range", "descending_command",
               "amplitude_rate_per_s")
    c = _mapping(spec, section, "control", line, allowed=allowed, required=("cpg_tags",))
    cpg_tags = c["cpg_tags"]
    if not isinstance(cpg_tags, list) or not cpg_tags:
        raise spec.fail(_line(c, "cpg_tags"), "control.cpg_tags", "no CPG tags", received=cpg_tags,
                        expected="a non-empty list of string tags")
    for t in cpg_tags:
        if str(t) not in string_tags:
            raise spec.fail(_line(c, "cpg_tags"), "control.cpg_tags", "no string config for this tag",
                            received=t, expected=f"a tag of string_materials: {sorted(string_tags)}")
    imp = _mapping(spec, c.get("impedance") or LineDict(), "control.impedance", _line(c, "impedance"))
    gains = _materials(spec, imp, "control.impedance", ImpedanceGains, _line(c, "impedance")) if imp else {}
    for t in cpg_tags:
        if str(t) not in gains:
            raise spec.fail(_line(c, "cpg_tags"), "control.impedance", "missing config for a CPG tag",
                            received=t, expected=f"an impedance entry for every CPG tag {list(cpg_tags)}")
    for t in gains:
        if t not in string_tags:
            raise spec.fail(_line(imp, t), f"control.impedance.{t}", "no string config for this tag",
                            received=t, expected=f"a tag of string_materials: {sorted(string_tags)}")
    kwargs: dict[str, Any] = {}
    for key in ("cpg_update_period_s", "descending_command", "amplitude_rate_per_s"):
        if key in c:
            kwargs[key] = _number(spec, c[key], f"control.{key}", _line(c, key))
    if "node_range" in c:
        rng = c["node_range"]
        if not isinstance(rng, list) or len(rng) != 2:
            raise spec.fail(_line(c, "node_range"), "control.node_range", "not a [lo, hi] pair", received=rng,
                            expected="two numbers")
        kwargs["node_range"] = tuple(_number(spec, v, "control.node_range", _line(c, "node_range"))
                                     for v in rng)
    try:
        return ControlSpec(cpg_tags=tuple(str(t) for t in cpg_tags), impedance=tuple(sorted(gains.items())),
                           **kwargs)
    except (ConfigError, MorphologySpecError) as exc:
        raise spec.fail(line, "control", str(exc), expected="a valid control section") from exc


# -- entry points --------------------------------------------------------------------------------
def parse_spec(text: str, source: str = "<string>", *, segments: int | None = None,
               name: str | None = None) -> Morphology:
    """Morphology from spec-file text. `segments` and `name` override the file's values."""
    spec = _Spec(source)
    doc = _mapping(spec, _compose(text, spec), "(document)", 1, allowed=TOP_KEYS,
                   required=("name", "segments", "joints", "rod_materials", "string_materials", "control"))
    seg = _mapping(spec, doc["segments"], "segments", _line(doc, "segments"),
                   allowed=("count", "nodes", "rods", "transforms"), required=("count", "nodes", "rods"))
    count = segments if segments is not None else seg["count"]
    if not isinstance(count, int) or isinstance(count, bool) or count < 2:
        raise spec.fail(_line(seg, "count"), "segments.count", "not an integer >= 2", received=count,
                        expected="the number of segments (at least 2, so there is a joint)")
    rod_tags = _materials(spec, doc["rod_materials"], "rod_materials", RodMaterial,
                          _line(doc, "rod_materials"))
    string_tags = _materials(spec, doc["string_materials"], "string_materials", StringMaterial,
                             _line(doc, "string_materials"))
    control = _control(spec, doc["control"], _line(doc, "control"), string_tags)
    names, points = _template_nodes(spec, seg["nodes"], _line(seg, "nodes"))
    template_rods = _template_rods(spec, seg["rods"], names, points, rod_tags, _line(seg, "rods"))
    template = np.array(points)
    per = len(names)
    nodes: list[np.ndarray] = []
    for i in range(count):
        pts = _transform(spec, seg.get("transforms"), "segments.transforms", _line(seg, "transforms"), i,
                         {"i": i, "n": count}, template)
        nodes.append(pts)
    all_pts = _transform(spec, doc.get("placement"), "placement", _line(doc, "placement"), None,
                         {"n": count}, np.vstack(nodes))
    rods = [Rod(i * per + a, i * per + b, t) for i in range(count) for a, b, t in template_rods]
    strings = _joint_strings(spec, doc["joints"], names, count, string_tags, control.cpg_tags,
                             _line(doc, "joints"))
    unused = sorted(set(string_tags) - {s.tag for s in strings})
    if unused:
        raise spec.fail(_line(doc, "string_materials"), "string_materials", "tags no joint uses",
                        received=unused, expected="every string tag used by a joints block")
    morph_name = name or str(doc["name"])
    try:
        structure = StructureSpec(
            name=morph_name, nodes=tuple(tuple(float(c) for c in p) for p in all_pts),
            node_segment=tuple(i for i in range(count) for _ in range(per)),
            node_names=tuple(f"s{i}.{n}" for i in range(count) for n in names),
            rods=tuple(rods), strings=tuple(strings), rod_materials=tuple(sorted(rod_tags.items())),
            string_materials=tuple(sorted(string_tags.items())))
    except MorphologySpecError as exc:
        raise spec.fail(_line(doc, "segments"), "segments", str(exc), expected="a valid structure") from exc
    scored = doc.get("scored_segment", "n // 2")
    scored_i = _number(spec, scored, "scored_segment", _line(doc, "scored_segment"), {"n": count})
    extra = _mapping(spec, doc.get("extra", LineDict()), "extra", _line(doc, "extra"))
    controllers = doc.get("controllers", ["ntrt"])
    if not isinstance(controllers, list) or not controllers:
        raise spec.fail(_line(doc, "controllers"), "controllers", "not a list of controller spaces",
                        received=controllers, expected="e.g. [ntrt]")
    try:
        return Morphology(
            name=morph_name, structure=structure, control=control, scored_segment=int(scored_i),
            duration_s=_number(spec, doc.get("duration_s", 30.0), "duration_s", _line(doc, "duration_s")),
            ground_friction=_number(spec, doc.get("ground_friction", 0.5), "ground_friction",
                                    _line(doc, "ground_friction")),
            controllers=tuple(str(c) for c in controllers),
            description=str(doc.get("description", "")).format(segments=count).strip(),
            extra=tuple(sorted((str(k), _number(spec, v, f"extra.{k}", _line(extra, k)))
                               for k, v in extra.items())),
        )
    except (ConfigError, MorphologySpecError) as exc:
        raise spec.fail(None, "(morphology)", str(exc), expected="a valid morphology") from exc


def load_spec_file(path: str | Path, *, segments: int | None = None, name: str | None = None) -> Morphology:
    """Morphology from a YAML spec file (see docs/morphology-format.md)."""
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise MorphologySpecError("cannot read the spec file", received=str(p),
                                  expected="a readable .yaml file") from exc
    if p.suffix.lower() not in (".yaml", ".yml"):
        raise MorphologySpecError("unsupported spec file type", received=p.suffix, expected=".yaml or .yml")
    return parse_spec(text, str(p), segments=segments, name=name)


def builtin_spec(stem: str, *, segments: int | None = None, name: str | None = None) -> Morphology:
    """A built-in morphology from worker/morphology/specs/<stem>.yaml."""
    return load_spec_file(SPEC_DIR / f"{stem}.yaml", segments=segments, name=name)
