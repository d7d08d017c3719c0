"""The explicit registry of built-in morphologies, and loading by name, dict or file."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from functools import lru_cache
from pathlib import Path

from protocol.errors import UnknownMorphologyError
from robot.morphology.model import Morphology
from robot.morphology.octahedral import octahedral_complex
from robot.morphology.ribbed import ribbed
from robot.morphology.tetrahedral import tetrahedral_complex
from robot.morphology.tetraspine import tetraspine, tetraspine_hardware

BUILTINS: dict[str, Callable[[], Morphology]] = {
    "tetraspine": lambda: tetraspine(12, name="tetraspine"),
    "tetraspine-ntrt": lambda: tetraspine(3, name="tetraspine-ntrt"),
    "tetraspine-hardware": tetraspine_hardware,
    "tetrahedral-complex": tetrahedral_complex,
    "octahedral-complex": octahedral_complex,
    "ribbed": ribbed,
}


@lru_cache(maxsize=32)
def _builtin(name: str) -> Morphology:
    return BUILTINS[name]()


def builtin_names() -> list[str]:
    return sorted(BUILTINS)


def load_morphology(source: str | Mapping | Morphology) -> Morphology:
    """A built-in name, a Morphology.to_dict() mapping, a spec file path, or a Morphology."""
    if isinstance(source, Morphology):
        return source
    if isinstance(source, Mapping):
        return Morphology.from_dict(source)
    if isinstance(source, str):
        if source in BUILTINS:
            return _builtin(source)
        path = Path(source)
        if path.suffix.lower() in (".yaml", ".yml", ".toml") and path.exists():
            from robot.morphology.specfile import load_spec_file

            return load_spec_file(path)
    raise UnknownMorphologyError("unknown morphology", received=source,
                                 expected=f"one of {builtin_names()} or a path to a .yaml spec file")
