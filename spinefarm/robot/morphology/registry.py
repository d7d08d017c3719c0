"""Built-in morphologies are the spec files under robot/morphology/specs/ (the file's stem is its
name); loading takes a built-in name, a Morphology.to_dict() mapping, a spec file path or a Morphology."""

from __future__ import annotations

from collections.abc import Mapping
from functools import lru_cache
from pathlib import Path

from spinefarm.protocol.errors import UnknownMorphologyError
from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.morphology.specfile import SPEC_DIR, load_spec_file, spec_document
from spinefarm.robot.morphology.specladder import DEFAULT_LADDER, RobotLadder, parse_ladder
from spinefarm.robot.morphology.specyaml import line_of


def builtin_names() -> list[str]:
    return sorted(p.stem for p in SPEC_DIR.glob("*.yaml"))


def builtin_path(name: str) -> Path:
    if name not in builtin_names():
        raise UnknownMorphologyError("unknown built-in morphology", received=name, expected=builtin_names())
    return SPEC_DIR / f"{name}.yaml"


@lru_cache(maxsize=32)
def _builtin(name: str) -> Morphology:
    return load_spec_file(builtin_path(name))


def load_morphology(source: str | Mapping | Morphology) -> Morphology:
    """A built-in name, a Morphology.to_dict() mapping, a spec file path, or a Morphology."""
    if isinstance(source, Morphology):
        return source
    if isinstance(source, Mapping):
        return Morphology.from_dict(source)
    if isinstance(source, str):
        if source in builtin_names():
            return _builtin(source)
        path = Path(source)
        if path.suffix.lower() in (".yaml", ".yml"):
            if path.exists():
                return load_spec_file(path)
            raise UnknownMorphologyError(  # a file name, never a built-in's: say the file is missing
                "spec file not found", received=source,
                expected=f"an existing .yaml spec file (there is none at {path.resolve()}), or a built-in name: "
                         f"{', '.join(builtin_names())} (`spinefarm spec NAME > FILE.yaml` starts a new one)")
    raise UnknownMorphologyError("unknown morphology", received=source,
                                 expected=f"one of {builtin_names()} or a path to a .yaml spec file")


def load_ladder(source: str) -> RobotLadder:
    """The screening ladder of a built-in or a spec file (its own `ladder:` or its base's), else the default
    (robot.morphology.specladder)."""
    if source in builtin_names():
        path: Path | None = builtin_path(source)
    else:
        path = Path(source) if Path(source).suffix.lower() in (".yaml", ".yml") else None
    if path is None:
        return DEFAULT_LADDER
    spec, doc = spec_document(path.read_text(encoding="utf-8"), str(path))  # its `base:`'s ladder if not its own
    return parse_ladder(spec, doc["ladder"], line_of(doc, "ladder")) if "ladder" in doc else DEFAULT_LADDER
