"""One search over body and gait (docs/codesign.md): the samplers see one vector, the gait's parameters first
and then the body constants a spec file's `search:` block frees; each trial's robot is built from its body.

A co-designed run carries its spec document (resolved of `base:`, as plain JSON) and its searched fields, so a
worker builds any body without the file, and a resumed run needs nothing but its run file.
"""

from __future__ import annotations

import dataclasses
import json
from collections import OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from spinefarm.protocol.errors import MorphologySpecError
from spinefarm.protocol.params import ParamSpace, ParamSpec
from spinefarm.protocol.run import RunConfig
from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.morphology.specfile import check_search, from_document, spec_document
from spinefarm.robot.morphology.specsearch import BodyField, with_body
from spinefarm.robot.morphology.specyaml import SpecSource

BODY_PREFIX = "body."  # a body constant's parameter name: this + its path in the spec file


def plain(value: Any) -> Any:
    """A spec document as plain JSON-ready data (the line-remembering containers dropped)."""
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [plain(v) for v in value]
    return value


@dataclass(frozen=True)
class BodySearch:
    """The spec document every body starts from (no search block) and the fields a search sets."""

    document: Mapping[str, Any]
    fields: tuple[BodyField, ...]
    source: str = "<run>"

    @classmethod
    def from_file(cls, path: str | Path) -> BodySearch | None:
        """The file's body search, or None when it has no `search:` block."""
        spec, doc = spec_document(Path(path).read_text(encoding="utf-8"), str(path))
        if "search" not in doc:
            return None
        found = check_search(spec, doc, from_document(spec, doc))
        return cls({k: v for k, v in plain(doc).items() if k != "search"}, found, Path(path).name)

    def to_dict(self) -> dict[str, Any]:
        # the document as JSON text: a spec's key order is meaning (node numbering, CPG order), and run configs
        # are stored and hashed with their keys sorted
        return {"document": json.dumps(self.document), "source": self.source,
                "fields": [[f.path, f.low, f.high] for f in self.fields]}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> BodySearch:
        try:
            return cls(json.loads(d["document"]),
                       tuple(BodyField(str(p), float(lo), float(hi)) for p, lo, hi in d["fields"]),
                       str(d.get("source", "<run>")))
        except (KeyError, TypeError, ValueError) as exc:
            raise MorphologySpecError("run's body search is malformed", received=repr(exc)[:120],
                                      expected="{document, fields: [[path, low, high], ...]}") from exc

    def param_specs(self) -> tuple[ParamSpec, ...]:
        return tuple(ParamSpec(BODY_PREFIX + f.path, f.low, f.high, f.unit, "body constant (search: block)")
                     for f in self.fields)

    def space(self, gait: ParamSpace) -> ParamSpace:
        """One vector: the gait's parameters, then the body's constants."""
        return ParamSpace(gait.name, gait.specs + self.param_specs())

    def body(self, values: Mapping[str, float]) -> Morphology:
        """The robot with these body constants (path -> value) written into the document."""
        return from_document(SpecSource(self.source), with_body(self.document, dict(values)))  # type: ignore[arg-type]

    def values(self, physical: np.ndarray) -> dict[str, float]:
        """path -> value of the body part of a physical vector (the last len(fields) values)."""
        tail = np.asarray(physical, dtype=float)[len(physical) - len(self.fields):]
        return {f.path: float(v) for f, v in zip(self.fields, tail, strict=True)}


def file_values(search: BodySearch) -> dict[str, float]:
    """path -> the value the spec document itself gives each searched field (1 for an unset scale)."""
    morph = search.body({})
    out = {}
    for f in search.fields:
        section, *tag, name = f.path.split(".")
        if section == "segments":
            out[f.path] = float(search.document["segments"].get(name, 1.0))
        else:
            s = morph.structure
            material = s.rod_material(tag[0]) if section == "rod_materials" else s.string_material(tag[0])
            out[f.path] = float(getattr(material, name))
    return out


def with_file_body(search: BodySearch, gait_unit: np.ndarray) -> np.ndarray:
    """A gait's unit vector followed by the file's own body, in the run's unit cube (an --enqueue'd start)."""
    values = file_values(search)
    body = []
    for f in search.fields:
        if not f.low <= values[f.path] <= f.high:
            raise MorphologySpecError(f"the file's own {f.path} is outside its search range", received=values[f.path],
                                      expected=f"a value in [{f.low:g}, {f.high:g}] to start an --enqueue'd gait on")
        body.append((values[f.path] - f.low) / (f.high - f.low))
    return np.concatenate([np.asarray(gait_unit, dtype=float), body])


class Bodies:
    """A co-designed run's trial vectors split into (robot, gait's unit vector); robots built once per body and
    kept, the most recent `size`."""

    def __init__(self, search: BodySearch, space: ParamSpace, size: int = 32) -> None:
        self.search, self.space, self.size = search, space, size
        self.n_gait = len(space) - len(search.fields)
        self._robots: OrderedDict[tuple[float, ...], Morphology] = OrderedDict()
        self.built = 0

    def split(self, unit: np.ndarray) -> tuple[Morphology, np.ndarray]:
        values = self.search.values(self.space.from_unit(unit))
        key = tuple(values.values())
        if key not in self._robots:
            self._robots[key] = self.search.body(values)
            self.built += 1
            while len(self._robots) > self.size:
                self._robots.popitem(last=False)
        self._robots.move_to_end(key)
        return self._robots[key], np.asarray(unit, dtype=float)[:self.n_gait]


def with_body_search(config: RunConfig, source: str) -> RunConfig:
    """A run of a spec file with a `search:` block searches its body with its gait; any other run is as given."""
    if config.is_test_objective or not source.lower().endswith((".yaml", ".yml")):
        return config
    search = BodySearch.from_file(source)
    if search is None:
        return config
    from spinefarm.robot.spaces import param_space

    space = search.space(param_space(Morphology.from_dict(config.morphology_spec), config.controller))
    return dataclasses.replace(config, param_space=tuple(space.describe()), space_hash=space.space_hash(),
                               body=search.to_dict())


def body_spec_text(search: BodySearch, values: Mapping[str, float], header: str) -> str:
    """A robot file of this body: the run's spec document with the values written in, no `search:` block.
    Floats are written as the shortest text that reads back as the same bits, so the file builds the very robot
    the trial ran."""
    import yaml

    from spinefarm.robot.morphology.specfile import TOP_KEYS

    doc = plain(with_body(search.document, dict(values)))  # type: ignore[arg-type]
    doc = {k: doc[k] for k in sorted(doc, key=lambda k: TOP_KEYS.index(k) if k in TOP_KEYS else len(TOP_KEYS))}
    comments = "".join(f"# {line}\n" for line in header.splitlines())
    return comments + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=120)


def body_of_trial(config: RunConfig, params_unit: np.ndarray) -> tuple[dict[str, float], np.ndarray]:
    """A co-designed trial's body constants (path -> value) and its gait's unit vector, as its worker split them."""
    from spinefarm.robot.spaces import param_space

    search = BodySearch.from_dict(config.body)
    bodies = Bodies(search, search.space(param_space(Morphology.from_dict(config.morphology_spec),
                                                     config.controller)))
    return search.values(bodies.space.from_unit(params_unit)), np.asarray(params_unit, dtype=float)[:bodies.n_gait]


def job_robot(job: Mapping[str, Any]) -> tuple[Morphology, np.ndarray]:
    """The robot and unit vector a re-simulation job (a picture, a motion: morphology, controller, params_unit and,
    for a co-designed run, its `body` search) runs: in a co-designed run the trial's own body and its gait."""
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.robot.spaces import param_space

    morph = load_morphology(job["morphology"])
    unit = np.asarray(job.get("params_unit", ()), dtype=float)
    if not job.get("body"):
        return morph, unit
    search = BodySearch.from_dict(job["body"])
    return Bodies(search, search.space(param_space(morph, job.get("controller"))), size=1).split(unit)
