"""Morphology spec files (YAML): a segment template repeated N times, joint string templates, materials
and controller defaults. The format is documented in docs/morphology-format.md.

Every error names the file, the line and the field, what was found and what was expected. Lines come
from PyYAML's node marks, kept by the containers of robot.morphology.specyaml.
"""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np
from spinefarm.protocol.errors import ConfigError, MorphologySpecError
from spinefarm.robot import fixedmath as fm
from spinefarm.robot.morphology.model import ControlSpec, ImpedanceGains, Morphology
from spinefarm.robot.morphology.specyaml import (
    LineDict,
    SpecSource,
    applies,
    compose,
    format_name,
    line_of,
    mapping,
    number,
    vector,
)
from spinefarm.robot.morphology.structure import (
    Rod,
    RodMaterial,
    String,
    StringMaterial,
    StructureSpec,
    rotation_matrix,
)

SPEC_DIR = Path(__file__).parent / "specs"
TOP_KEYS = ("base", "name", "description", "segments", "placement", "joints", "rod_materials", "string_materials",
            "control", "scored_segment", "duration_s", "ground_friction", "controllers", "extra")


# -- segment template ----------------------------------------------------------------------------
def _template_nodes(spec: SpecSource, nodes: Any, line: int | None) -> tuple[list[str], list[np.ndarray]]:
    nodes = mapping(spec, nodes, "segments.nodes", line)
    names: list[str] = []
    points: list[np.ndarray] = []
    for key, value in nodes.items():
        kline = line_of(nodes, key)
        field = f"segments.nodes.{key}"
        if isinstance(value, dict):
            series = mapping(spec, value, field, kline, allowed=("count", "at"), required=("count", "at"))
            count = series["count"]
            if not isinstance(count, int) or count < 1:
                raise spec.fail(line_of(series, "count"), f"{field}.count", "not a positive integer",
                                received=count, expected="an integer >= 1")
            if "{" not in str(key):
                raise spec.fail(kline, field, "a node series needs {k} in its name", received=key,
                                expected="a name like 'rib_{k}'")
            for k in range(count):
                names.append(format_name(spec, str(key), k, field, kline))
                points.append(vector(spec, series["at"], f"{field}.at", line_of(series, "at"), {"k": k}))
        else:
            names.append(str(key))
            points.append(vector(spec, value, field, kline))
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise spec.fail(line, "segments.nodes", "node names repeat", received=dup, expected="unique names")
    return names, points


def _template_rods(spec: SpecSource, rods: Any, names: list[str], points: list[np.ndarray], rod_tags: dict,
                   line: int | None) -> list[tuple[int, int, str]]:
    if not isinstance(rods, list) or not rods:
        raise spec.fail(line, "segments.rods", "no rods", received=rods, expected="a non-empty list")
    index = {n: i for i, n in enumerate(names)}
    out = []
    for r, entry in enumerate(rods):
        rline = line_of(rods, r)
        field = f"segments.rods[{r}]"
        if isinstance(entry, list):
            if len(entry) != 3:
                raise spec.fail(rline, field, "not [from, to, tag]", received=entry, expected="3 items")
            ends, tag, count = (entry[0], entry[1]), entry[2], None
        else:
            m = mapping(spec, entry, field, rline, allowed=("from", "to", "tag", "count"),
                         required=("from", "to", "tag"))
            ends, tag, count = (m["from"], m["to"]), m["tag"], m.get("count")
        if count is not None and (not isinstance(count, int) or count < 1):
            raise spec.fail(rline, f"{field}.count", "not a positive integer", received=count,
                            expected="an integer >= 1")
        for k in range(count or 1):
            pair = [format_name(spec, str(e), k, field, rline) if count else str(e) for e in ends]
            for name in pair:
                if name not in index:
                    raise spec.fail(rline, field, "unknown node", received=name,
                                    expected=f"a node of segments.nodes: {names}")
            a, b = index[pair[0]], index[pair[1]]
            if fm.norm(points[a] - points[b]) < 1e-9:
                raise spec.fail(rline, field, "rod of zero length", received=f"{pair[0]} -> {pair[1]}",
                                expected="two nodes at different points (length > 0 cm)")
            if str(tag) not in rod_tags:
                raise spec.fail(rline, f"{field}.tag", "no rod config for this tag", received=tag,
                                expected=f"a tag of rod_materials: {sorted(rod_tags)}")
            out.append((a, b, str(tag)))
    return out


def _transform(spec: SpecSource, steps: Any, field: str, line: int | None, index: int | None,
               names: dict[str, float], pts: np.ndarray) -> np.ndarray:
    """Apply a list of {translate | rotate, when} steps to pts (n, 3) cm."""
    if steps is None:
        return pts
    if not isinstance(steps, list):
        raise spec.fail(line, field, "not a list of transforms", received=steps,
                        expected="a list of {translate: [x, y, z]} or {rotate: {axis, degrees}}")
    for t, step in enumerate(steps):
        tline = line_of(steps, t)
        tfield = f"{field}[{t}]"
        m = mapping(spec, step, tfield, tline, allowed=("translate", "rotate", "when"))
        kinds = [k for k in ("translate", "rotate") if k in m]
        if len(kinds) != 1:
            raise spec.fail(tline, tfield, "needs exactly one of translate or rotate", received=sorted(m),
                            expected="translate or rotate (and optionally when)")
        if index is not None and not applies(spec, m.get("when", "all"), index, f"{tfield}.when",
                                              line_of(m, "when")):
            continue
        if index is None and "when" in m:
            raise spec.fail(tline, f"{tfield}.when", "placement applies to every node", received=m["when"],
                            expected="no 'when' in placement")
        if "translate" in m:
            pts = pts + vector(spec, m["translate"], f"{tfield}.translate", line_of(m, "translate"), names)
        else:
            rot = mapping(spec, m["rotate"], f"{tfield}.rotate", line_of(m, "rotate"),
                           allowed=("axis", "degrees", "about"), required=("axis", "degrees"))
            rline = line_of(rot)
            axis = vector(spec, rot["axis"], f"{tfield}.rotate.axis", rline, names)
            if fm.norm(axis) == 0.0:
                raise spec.fail(rline, f"{tfield}.rotate.axis", "zero axis", received=list(axis),
                                expected="a non-zero direction")
            angle = np.radians(number(spec, rot["degrees"], f"{tfield}.rotate.degrees", rline, names))
            r = rotation_matrix(tuple(axis), float(angle))
            if "about" in rot:
                about = vector(spec, rot["about"], f"{tfield}.rotate.about", rline, names)
                pts = fm.rotate_rows(pts - about, r) + about
            else:
                pts = fm.rotate_rows(pts, r)
    return pts


# -- joints --------------------------------------------------------------------------------------
def _joint_strings(spec: SpecSource, joints: Any, names: list[str], n_segments: int, string_tags: dict,
                   cpg_tags: tuple[str, ...], line: int | None) -> list[String]:
    """Strings of every joint. Passive (non-CPG) strings come first, as NTRT creates them; within each
    group joint by joint, and within a joint in the order the blocks list them."""
    if not isinstance(joints, list) or not joints:
        raise spec.fail(line, "joints", "no joint strings", received=joints, expected="a non-empty list")
    index = {n: i for i, n in enumerate(names)}
    per = len(names)
    blocks = []
    for j, block in enumerate(joints):
        jline = line_of(joints, j)
        field = f"joints[{j}]"
        m = mapping(spec, block, field, jline, allowed=("tag", "strings", "when", "span"),
                     required=("tag", "strings"))
        tag = str(m["tag"])
        if tag not in string_tags:
            raise spec.fail(line_of(m, "tag"), f"{field}.tag", "no string config for this tag", received=tag,
                            expected=f"a tag of string_materials: {sorted(string_tags)}")
        span = m.get("span", 1)
        if not isinstance(span, int) or isinstance(span, bool):
            raise spec.fail(line_of(m, "span"), f"{field}.span", "not an integer", received=span,
                            expected="segments between the two ends (>= 1)")
        if span == 0:
            raise spec.fail(line_of(m, "span"), f"{field}.span", "string joining a body to itself",
                            received=span, expected="span >= 1 (ends on two different segments)")
        if not 1 <= span < n_segments:
            raise spec.fail(line_of(m, "span"), f"{field}.span", "span out of range", received=span,
                            expected=f"an integer in [1, {n_segments - 1}]")
        pairs = m["strings"]
        if not isinstance(pairs, list) or not pairs:
            raise spec.fail(line_of(m, "strings"), f"{field}.strings", "no strings", received=pairs,
                            expected="a list of [node on segment s, node on segment s + span]")
        resolved = []
        for p, pair in enumerate(pairs):
            pline = line_of(pairs, p)
            if not isinstance(pair, list) or len(pair) != 2:
                raise spec.fail(pline, f"{field}.strings[{p}]", "not a [from, to] pair", received=pair,
                                expected="two node names")
            for name in pair:
                if str(name) not in index:
                    raise spec.fail(pline, f"{field}.strings[{p}]", "unknown node", received=name,
                                    expected=f"a node of segments.nodes: {names}")
            resolved.append((index[str(pair[0])], index[str(pair[1])]))
        applies(spec, m.get("when", "all"), 0, f"{field}.when", line_of(m, "when"))
        blocks.append((tag, span, m.get("when", "all"), resolved, jline))
    out: list[String] = []
    for cpg_group in (False, True):
        for s in range(n_segments - 1):
            for tag, span, when, resolved, jline in blocks:
                if (tag in cpg_tags) != cpg_group or s + span >= n_segments:
                    continue
                if applies(spec, when, s, "joints.when", jline):
                    out.extend(String(s * per + a, (s + span) * per + b, tag) for a, b in resolved)
    return out


# -- materials and control -----------------------------------------------------------------------
def _materials(spec: SpecSource, section: Any, name: str, cls: type, line: int | None) -> dict:
    section = mapping(spec, section, name, line)
    if not section:
        raise spec.fail(line, name, "no materials", expected="at least one tag")
    allowed = tuple(f.name for f in fields(cls))
    out = {}
    for tag, value in section.items():
        field = f"{name}.{tag}"
        m = mapping(spec, value if value is not None else LineDict(), field, line_of(section, tag),
                     allowed=allowed)
        kwargs = {k: (None if v is None else number(spec, v, f"{field}.{k}", line_of(m, k)))
                  for k, v in m.items()}
        try:
            out[str(tag)] = cls(**kwargs)
        except ConfigError as exc:
            raise spec.fail(line_of(section, tag), field, str(exc),
                            expected=f"valid {cls.__name__} fields") from exc
    return out


def _control(spec: SpecSource, section: Any, line: int | None, string_tags: dict) -> ControlSpec:
    allowed = ("cpg_tags", "impedance", "cpg_update_period_s", "node_range", "descending_command",
               "amplitude_rate_per_s")
    c = mapping(spec, section, "control", line, allowed=allowed, required=("cpg_tags",))
    cpg_tags = c["cpg_tags"]
    if not isinstance(cpg_tags, list) or not cpg_tags:
        raise spec.fail(line_of(c, "cpg_tags"), "control.cpg_tags", "no CPG tags", received=cpg_tags,
                        expected="a non-empty list of string tags")
    for t in cpg_tags:
        if str(t) not in string_tags:
            raise spec.fail(line_of(c, "cpg_tags"), "control.cpg_tags", "no string config for this tag",
                            received=t, expected=f"a tag of string_materials: {sorted(string_tags)}")
    imp = mapping(spec, c.get("impedance") or LineDict(), "control.impedance", line_of(c, "impedance"))
    gains = _materials(spec, imp, "control.impedance", ImpedanceGains, line_of(c, "impedance")) if imp else {}
    for t in cpg_tags:
        if str(t) not in gains:
            raise spec.fail(line_of(c, "cpg_tags"), "control.impedance", "missing config for a CPG tag",
                            received=t, expected=f"an impedance entry for every CPG tag {list(cpg_tags)}")
    for t in gains:
        if t not in string_tags:
            raise spec.fail(line_of(imp, t), f"control.impedance.{t}", "no string config for this tag",
                            received=t, expected=f"a tag of string_materials: {sorted(string_tags)}")
    kwargs: dict[str, Any] = {}
    for key in ("cpg_update_period_s", "descending_command", "amplitude_rate_per_s"):
        if key in c:
            kwargs[key] = number(spec, c[key], f"control.{key}", line_of(c, key))
    if "node_range" in c:
        rng = c["node_range"]
        if not isinstance(rng, list) or len(rng) != 2:
            raise spec.fail(line_of(c, "node_range"), "control.node_range", "not a [lo, hi] pair", received=rng,
                            expected="two numbers")
        kwargs["node_range"] = tuple(number(spec, v, "control.node_range", line_of(c, "node_range"))
                                     for v in rng)
    try:
        return ControlSpec(cpg_tags=tuple(str(t) for t in cpg_tags), impedance=tuple(sorted(gains.items())),
                           **kwargs)
    except (ConfigError, MorphologySpecError) as exc:
        raise spec.fail(line, "control", str(exc), expected="a valid control section") from exc


# -- inheritance ---------------------------------------------------------------------------------
def _merged(base: Any, override: Any) -> Any:
    """`override` laid over `base`: mappings merge key by key, anything else replaces."""
    if not (isinstance(base, dict) and isinstance(override, dict)):
        return override
    out = LineDict({**base})
    out.line, out.key_lines = getattr(override, "line", 0), {**getattr(base, "key_lines", {}),
                                                              **getattr(override, "key_lines", {})}
    for key, value in override.items():
        out[key] = _merged(base[key], value) if key in base else value
    return out


def _with_base(spec: SpecSource, doc: LineDict, seen: set[str]) -> LineDict:
    """A document with `base: NAME` (a built-in spec, or a .yaml path relative to this file) is that
    spec with this document's keys laid over it."""
    if "base" not in doc:
        return doc
    base = doc["base"]
    line = line_of(doc, "base")
    here = Path(spec.source).parent if spec.source != "<string>" else Path.cwd()
    path = SPEC_DIR / f"{base}.yaml" if (SPEC_DIR / f"{base}.yaml").is_file() else here / str(base)
    if not isinstance(base, str) or not path.is_file():
        raise spec.fail(line, "base", "no such spec to start from", received=base,
                        expected=f"a built-in ({', '.join(sorted(p.stem for p in SPEC_DIR.glob('*.yaml')))}) "
                                 "or a .yaml path relative to this file")
    key = str(path.resolve())
    if key in seen:
        raise spec.fail(line, "base", "specs inherit from each other in a cycle", received=base,
                        expected="a chain of bases that ends")
    base_spec = SpecSource(str(path))
    base_doc = _with_base(base_spec, mapping(base_spec, compose(path.read_text(), base_spec), "(document)", 1,
                                             allowed=TOP_KEYS), seen | {key})
    merged = _merged(base_doc, LineDict({k: v for k, v in doc.items() if k != "base"}))
    merged.key_lines = {**base_doc.key_lines, **doc.key_lines}
    return merged


# -- entry points --------------------------------------------------------------------------------
def parse_spec(text: str, source: str = "<string>", *, segments: int | None = None,
               name: str | None = None) -> Morphology:
    """Morphology from spec-file text. `segments` and `name` override the file's values."""
    spec = SpecSource(source)
    doc = _with_base(spec, mapping(spec, compose(text, spec), "(document)", 1, allowed=TOP_KEYS), set())
    doc = mapping(spec, doc, "(document)", 1, allowed=TOP_KEYS,
                   required=("name", "segments", "joints", "rod_materials", "string_materials", "control"))
    seg = mapping(spec, doc["segments"], "segments", line_of(doc, "segments"),
                   allowed=("count", "nodes", "rods", "transforms"), required=("count", "nodes", "rods"))
    count = segments if segments is not None else seg["count"]
    if not isinstance(count, int) or isinstance(count, bool) or count < 2:
        raise spec.fail(line_of(seg, "count"), "segments.count", "not an integer >= 2", received=count,
                        expected="the number of segments (at least 2, so there is a joint)")
    rod_tags = _materials(spec, doc["rod_materials"], "rod_materials", RodMaterial,
                          line_of(doc, "rod_materials"))
    string_tags = _materials(spec, doc["string_materials"], "string_materials", StringMaterial,
                             line_of(doc, "string_materials"))
    control = _control(spec, doc["control"], line_of(doc, "control"), string_tags)
    names, points = _template_nodes(spec, seg["nodes"], line_of(seg, "nodes"))
    template_rods = _template_rods(spec, seg["rods"], names, points, rod_tags, line_of(seg, "rods"))
    template = np.array(points)
    per = len(names)
    nodes: list[np.ndarray] = []
    for i in range(count):
        pts = _transform(spec, seg.get("transforms"), "segments.transforms", line_of(seg, "transforms"), i,
                         {"i": i, "n": count}, template)
        nodes.append(pts)
    all_pts = _transform(spec, doc.get("placement"), "placement", line_of(doc, "placement"), None,
                         {"n": count}, np.vstack(nodes))
    rods = [Rod(i * per + a, i * per + b, t) for i in range(count) for a, b, t in template_rods]
    strings = _joint_strings(spec, doc["joints"], names, count, string_tags, control.cpg_tags,
                             line_of(doc, "joints"))
    unused = sorted(set(string_tags) - {s.tag for s in strings})
    if unused:
        raise spec.fail(line_of(doc, "string_materials"), "string_materials", "tags no joint uses",
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
        raise spec.fail(line_of(doc, "segments"), "segments", str(exc), expected="a valid structure") from exc
    scored = doc.get("scored_segment", "n // 2")
    scored_i = number(spec, scored, "scored_segment", line_of(doc, "scored_segment"), {"n": count})
    extra = mapping(spec, doc.get("extra", LineDict()), "extra", line_of(doc, "extra"))
    controllers = doc.get("controllers", ["ntrt"])
    if not isinstance(controllers, list) or not controllers:
        raise spec.fail(line_of(doc, "controllers"), "controllers", "not a list of controller spaces",
                        received=controllers, expected="e.g. [ntrt]")
    try:
        return Morphology(
            name=morph_name, structure=structure, control=control, scored_segment=int(scored_i),
            duration_s=number(spec, doc.get("duration_s", 30.0), "duration_s", line_of(doc, "duration_s")),
            ground_friction=number(spec, doc.get("ground_friction", 0.5), "ground_friction",
                                    line_of(doc, "ground_friction")),
            controllers=tuple(str(c) for c in controllers),
            description=str(doc.get("description", "")).format(segments=count).strip(),
            extra=tuple(sorted((str(k), number(spec, v, f"extra.{k}", line_of(extra, k)))
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
    """A built-in morphology from robot/morphology/specs/<stem>.yaml."""
    return load_spec_file(SPEC_DIR / f"{stem}.yaml", segments=segments, name=name)
