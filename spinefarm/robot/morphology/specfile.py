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
from spinefarm.robot.morphology.bodycheck import static_problem
from spinefarm.robot.morphology.model import ControlSpec, ImpedanceGains, Morphology
from spinefarm.robot.morphology.specladder import parse_ladder
from spinefarm.robot.morphology.specsearch import BodyField, parse_search, with_body
from spinefarm.robot.morphology.specstructure import build_structure
from spinefarm.robot.morphology.specyaml import (
    LineDict,
    SpecSource,
    compose,
    line_of,
    mapping,
    number,
)
from spinefarm.robot.morphology.structure import (
    RodMaterial,
    StringMaterial,
    StructureSpec,
)

SPEC_DIR = Path(__file__).parent / "specs"
TOP_KEYS = ("base", "name", "description", "segments", "placement", "joints", "rod_materials", "string_materials",
            "control", "scored_segment", "duration_s", "ground_friction", "controllers", "extra", "search", "ladder")
BODY_PROBES = 5  # values tried along each searched range before it is said to admit no valid body
SEGMENT_KEYS = ("count", "nodes", "rods", "transforms", "rod_length_scale", "spacing_scale")


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
    try:
        base_text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise spec.fail(line, "base", "cannot read the spec to start from", received=str(path),
                        expected="a readable UTF-8 .yaml file") from exc
    base_doc = _with_base(base_spec, mapping(base_spec, compose(base_text, base_spec), "(document)", 1,
                                             allowed=TOP_KEYS), seen | {key})
    merged = _merged(base_doc, LineDict({k: v for k, v in doc.items() if k != "base"}))
    if "ladder" in doc:  # a ladder of its own replaces the base's whole: the base's measurement is not its own
        merged["ladder"] = doc["ladder"]
    merged.key_lines = {**base_doc.key_lines, **doc.key_lines}
    return merged


# -- entry points --------------------------------------------------------------------------------
def spec_document(text: str, source: str = "<string>") -> tuple[SpecSource, LineDict]:
    """A spec file's document with its `base:` resolved, each value remembering its line."""
    spec = SpecSource(source)
    doc = _with_base(spec, mapping(spec, compose(text, spec), "(document)", 1, allowed=TOP_KEYS), set())
    return spec, doc


def parse_spec(text: str, source: str = "<string>", *, segments: int | None = None,
               name: str | None = None) -> Morphology:
    """Morphology from spec-file text. `segments` and `name` override the file's values. A `search:` block is
    checked (robot.morphology.specsearch) and is no part of the robot, nor is a `ladder:` block
    (robot.morphology.specladder), checked here too."""
    spec, doc = spec_document(text, source)
    morph = from_document(spec, doc, segments=segments, name=name)
    if "ladder" in doc:
        parse_ladder(spec, doc["ladder"], line_of(doc, "ladder"))
    if "search" in doc:
        check_search(spec, doc, morph, segments=segments, name=name)
    return morph


def search_fields(spec: SpecSource, doc: LineDict, morph: Morphology) -> tuple[BodyField, ...]:
    s = morph.structure
    return parse_search(spec, doc["search"], line_of(doc, "search"), dict(s.rod_materials), dict(s.string_materials))


def check_search(spec: SpecSource, doc: LineDict, morph: Morphology, **overrides: Any) -> tuple[BodyField, ...]:
    """The search block's fields, each range holding at least one body that builds and passes the static
    checks (five values from low to high, the other constants as the file has them)."""
    found = search_fields(spec, doc, morph)
    for f in found:
        why = ""
        for value in np.linspace(f.low, f.high, BODY_PROBES):
            try:
                body = from_document(spec, with_body(doc, {f.path: float(value)}), **overrides)
                why = static_problem(body.structure) or ""
            except (ConfigError, MorphologySpecError) as exc:
                why = str(exc)
            if not why:
                break
            why = f"at {value:g}: {why}"
        if why:
            raise spec.fail(f.line, f"search.{f.path}", "the range admits no valid body", received=[f.low, f.high],
                            expected=f"a range holding a body that builds ({why})")
    return found


def from_document(spec: SpecSource, doc: LineDict, *, segments: int | None = None,
                  name: str | None = None) -> Morphology:
    """The robot a resolved spec document describes."""
    doc = mapping(spec, doc, "(document)", 1, allowed=TOP_KEYS,
                   required=("name", "segments", "joints", "rod_materials", "string_materials", "control"))
    seg = mapping(spec, doc["segments"], "segments", line_of(doc, "segments"),
                   allowed=SEGMENT_KEYS, required=("count", "nodes", "rods"))
    count = segments if segments is not None else seg["count"]
    if not isinstance(count, int) or isinstance(count, bool) or count < 2:
        raise spec.fail(line_of(seg, "count"), "segments.count", "not an integer >= 2", received=count,
                        expected="the number of segments (at least 2, so there is a joint)")
    rod_tags = _materials(spec, doc["rod_materials"], "rod_materials", RodMaterial,
                          line_of(doc, "rod_materials"))
    string_tags = _materials(spec, doc["string_materials"], "string_materials", StringMaterial,
                             line_of(doc, "string_materials"))
    control = _control(spec, doc["control"], line_of(doc, "control"), string_tags)
    structure = build_structure(spec, doc, seg, count, name or str(doc["name"]), rod_tags, string_tags, control)
    return _morphology(spec, doc, structure, control, count)


def _morphology(spec: SpecSource, doc: LineDict, structure: StructureSpec, control: ControlSpec,
                count: int) -> Morphology:
    """The structure with its control, scored segment, trial defaults and controller spaces."""
    morph_name = structure.name
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
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:  # a folder, no permission, a binary file
        why = exc.strerror if isinstance(exc, OSError) and exc.strerror else "not UTF-8 text"
        raise MorphologySpecError(f"cannot read the spec file ({why})", received=str(p),
                                  expected="a readable UTF-8 .yaml file") from exc
    if p.suffix.lower() not in (".yaml", ".yml"):
        raise MorphologySpecError("unsupported spec file type", received=p.suffix, expected=".yaml or .yml")
    return parse_spec(text, str(p), segments=segments, name=name)


def load_search(path: str | Path) -> tuple[BodyField, ...]:
    """The checked `search:` block of a spec file (docs/morphology-format.md), or () when it has none."""
    p = Path(path)
    spec, doc = spec_document(p.read_text(encoding="utf-8"), str(p))
    if "search" not in doc:
        return ()
    return check_search(spec, doc, from_document(spec, doc))
