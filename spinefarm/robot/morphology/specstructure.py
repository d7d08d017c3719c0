"""The structure half of a spec file: the segment template (nodes, rods, per-segment transforms) repeated
N times and placed, joined by the joints' string templates (docs/morphology-format.md).

Errors name the file, the line and the field, as everywhere in spec files (robot.morphology.specfile).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from spinefarm.protocol.errors import MorphologySpecError
from spinefarm.robot import fixedmath as fm
from spinefarm.robot.morphology.model import ControlSpec
from spinefarm.robot.morphology.specyaml import (
    LineDict,
    SpecSource,
    applies,
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


def _scale(spec: SpecSource, seg: LineDict, key: str) -> float:
    """segments.rod_length_scale or segments.spacing_scale: a factor > 0, default 1 (the file as written)."""
    if key not in seg:
        return 1.0
    value = number(spec, seg[key], f"segments.{key}", line_of(seg, key))
    if not 0.0 < value <= 100.0:
        raise spec.fail(line_of(seg, key), f"segments.{key}", "scale out of range", received=value,
                        expected="a factor in (0, 100] (1 keeps the file's geometry)")
    return value


def build_structure(spec: SpecSource, doc: LineDict, seg: LineDict, count: int, morph_name: str,
               rod_tags: dict[str, RodMaterial], string_tags: dict[str, StringMaterial],
               control: ControlSpec) -> StructureSpec:
    """The template segment repeated `count` times, placed, and joined by the joints' strings."""
    names, points = _template_nodes(spec, seg["nodes"], line_of(seg, "nodes"))
    template_rods = _template_rods(spec, seg["rods"], names, points, rod_tags, line_of(seg, "rods"))
    length_scale, spacing_scale = (_scale(spec, seg, key) for key in ("rod_length_scale", "spacing_scale"))
    # the segment frame's origin rides along as the last row: spacing scales its offset from segment 0's
    template = np.vstack([np.array(points) * length_scale, np.zeros((1, 3))])
    per = len(names)
    nodes: list[np.ndarray] = []
    for i in range(count):
        pts = _transform(spec, seg.get("transforms"), "segments.transforms", line_of(seg, "transforms"), i,
                         {"i": i, "n": count}, template)
        nodes.append(pts)
    nodes = [pts[:-1] + (spacing_scale - 1.0) * (pts[-1] - nodes[0][-1]) for pts in nodes]
    all_pts = _transform(spec, doc.get("placement"), "placement", line_of(doc, "placement"), None,
                         {"n": count}, np.vstack(nodes))
    rods = [Rod(i * per + a, i * per + b, t) for i in range(count) for a, b, t in template_rods]
    strings = _joint_strings(spec, doc["joints"], names, count, string_tags, control.cpg_tags,
                             line_of(doc, "joints"))
    unused = sorted(set(string_tags) - {s.tag for s in strings})
    if unused:
        raise spec.fail(line_of(doc, "string_materials"), "string_materials", "tags no joint uses",
                        received=unused, expected="every string tag used by a joints block")
    try:
        return StructureSpec(
            name=morph_name, nodes=tuple(tuple(float(c) for c in p) for p in all_pts),
            node_segment=tuple(i for i in range(count) for _ in range(per)),
            node_names=tuple(f"s{i}.{n}" for i in range(count) for n in names),
            rods=tuple(rods), strings=tuple(strings), rod_materials=tuple(sorted(rod_tags.items())),
            string_materials=tuple(sorted(string_tags.items())))
    except MorphologySpecError as exc:
        raise spec.fail(line_of(doc, "segments"), "segments", str(exc), expected="a valid structure") from exc
