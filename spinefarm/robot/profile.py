"""Profiles: named physical constants laid over a robot's spec, e.g. what `spinefarm fit` found.

A profile file is YAML: `constants: {NAME: value}` (and optional `robot:`, `description:` for people). NAME is one
of CONSTANTS, for the rod and string materials optionally narrowed to one tag (`string_stiffness_n_per_m.outer`;
without a tag every tag takes the value). Engine constants (`mujoco.solref_time_s`) apply only in that engine.
Every constant has a plausible range with its source (docs/fitting.md); a value outside it is refused.
Engine-free: a coordinator loads, checks and hashes a profile; the trial config carries it to the workers.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import yaml

from spinefarm.protocol.errors import ConfigError
from spinefarm.robot.morphology.model import Morphology


@dataclass(frozen=True)
class Constant:
    """One constant a profile may set: where it lives (`spec`: a top-level spec key, `rod` / `string`: a
    material field of every tag or one, or an engine's name: that engine's option), its field, and its
    plausible range [low, high] with the source of that range."""

    where: str
    field: str
    low: float
    high: float
    source: str


CONSTANTS: dict[str, Constant] = {
    "ground_friction": Constant("spec", "ground_friction", 0.1, 1.5,
                                "Coulomb friction of floors against rubber, plastic or aluminium 0.2-1.0; NTRT's "
                                "ground 0.5 (Bullet's default, ntrt-spec.md section 1)"),
    "rod_friction": Constant("rod", "friction", 0.1, 1.5, "as the ground; NTRT's rods 0.5-1.0 (ntrt-spec.md)"),
    "rod_density_kg_per_cm3": Constant("rod", "density_kg_per_cm3", 0.0005, 0.02,
                                       "wood 0.0005, aluminium 0.0027, the hardware's rods 0.00311, steel 0.0079, "
                                       "NTRT's [P] rods 0.014 (ntrt-spec.md)"),
    "string_stiffness_n_per_m": Constant("string", "stiffness_n_per_m", 100.0, 1.0e6,
                                         "NTRT's strings 1000 N/m (ntrt-spec.md), the hardware's cables and "
                                         "springs 600000 N/m (tetraspine-hardware.yaml)"),
    "string_damping_n_s_per_m": Constant("string", "damping_n_s_per_m", 0.0, 100.0,
                                         "NTRT's strings 10 N s/m (ntrt-spec.md)"),
    "max_tension_n": Constant("string", "max_tension_n", 1.0, 200.0,
                              "NTRT's motors 10-70 N (T_max 1000-7000 kg cm/s^2, ntrt-spec.md)"),
    "motor_speed_cm_s": Constant("string", "motor_speed_cm_s", 1.0, 100.0,
                                 "NTRT's motors 7-100 cm/s (ntrt-spec.md)"),
    "motor_accel_cm_s2": Constant("string", "motor_accel_cm_s2", 100.0, 50000.0,
                                  "NTRT's motors 4000-10000 cm/s^2 (ntrt-spec.md)"),
    "mujoco.solref_time_s": Constant("mujoco", "solref_time_s", 0.002, 0.05,
                                     "MuJoCo's contact time constant: its default 0.02 s, at least two steps"),
    "mujoco.solref_damping_ratio": Constant("mujoco", "solref_damping_ratio", 0.1, 2.0,
                                            "MuJoCo's contact damping ratio: its default 1 (critical)"),
    "bullet.erp": Constant("bullet", "erp", 0.05, 0.8, "Bullet's contact error reduction: its default 0.2"),
}
MATERIALS = {"rod": "rod_materials", "string": "string_materials"}


def constant(name: str) -> tuple[Constant, str | None]:
    """(the constant, its tag or None) of a profile name; a one-line error naming the known ones."""
    if name in CONSTANTS:
        return CONSTANTS[name], None
    base, _, tag = name.partition(".")
    c = CONSTANTS.get(base)
    if c is None or c.where not in MATERIALS or not tag:
        raise ConfigError("unknown profile constant", received=name,
                          expected=f"one of {sorted(CONSTANTS)} (material ones optionally .TAG)")
    return c, tag


def check_constants(constants: Mapping[str, float]) -> dict[str, float]:
    """The constants as {name: float}, each a known name with a number inside its plausible range."""
    if not isinstance(constants, Mapping):
        raise ConfigError("profile constants are not a mapping", received=type(constants).__name__,
                          expected="{NAME: number}")
    out = {}
    for name, value in constants.items():
        c, _ = constant(str(name))
        if isinstance(value, bool) or not isinstance(value, int | float) or not c.low <= value <= c.high:
            raise ConfigError(f"profile constant {name} is outside its plausible range", received=value,
                              expected=f"a number in [{c.low:g}, {c.high:g}] ({c.source})")
        out[str(name)] = float(value)
    return dict(sorted(out.items()))


PROFILES_DIR = Path(__file__).parent / "profiles"  # the built-in profiles, shipped in the wheel (package data)


def builtin_profiles(folder: Path = PROFILES_DIR) -> list[str]:
    """The built-in profiles' names (their files' stems)."""
    return sorted(f.stem for f in folder.glob("*.yaml"))


def profile_path(name_or_path: Path | str, folder: Path = PROFILES_DIR) -> Path:
    """A profile's file: the path itself when it is one, else the built-in profile of that name (a user's file
    wins over a built-in of the same name, as a spec file does over a built-in robot)."""
    path = Path(name_or_path)
    if path.is_file():
        return path
    builtin = folder / f"{path.name}.yaml"
    if str(path) == path.name and not path.suffix and builtin.is_file():
        return builtin
    raise ConfigError("no profile file or built-in profile of that name", received=str(name_or_path),
                      expected=f"a YAML file's path or one of {builtin_profiles(folder)}")


def load_profile(path: Path | str, folder: Path = PROFILES_DIR) -> dict[str, float]:
    """A profile's constants (a file's path or a built-in's name), checked (unknown keys and names, values outside
    their ranges refused)."""
    path = profile_path(path, folder)
    try:
        doc = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ConfigError("cannot read the profile", received=f"{path}: {exc}".splitlines()[0],
                          expected="a readable YAML file with constants: {NAME: value}") from exc
    if not isinstance(doc, dict) or "constants" not in doc or set(doc) - {"constants", "robot", "description"}:
        raise ConfigError(f"{path} is not a profile", received=sorted(doc) if isinstance(doc, dict) else doc,
                          expected="keys constants (and optional robot, description)")
    return check_constants(doc["constants"] or {})


def profile_hash(constants: Mapping[str, float]) -> str:
    """16 hex digits of the constants' canonical JSON ("" for no profile)."""
    if not constants:
        return ""
    blob = json.dumps(dict(sorted(constants.items())), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def apply_to_spec(spec: dict, constants: Mapping[str, float]) -> dict:
    """A morphology dict (Morphology.to_dict) with the profile's spec and material constants laid over it;
    engine constants are left to engine_options()."""
    out = json.loads(json.dumps(spec))
    for name, value in constants.items():
        c, tag = constant(name)
        if c.where == "spec":
            out[c.field] = value
        elif c.where in MATERIALS:
            materials = out["structure"][MATERIALS[c.where]]
            if tag is not None and tag not in materials:
                raise ConfigError(f"profile constant {name} names a tag the robot lacks", received=tag,
                                  expected=f"one of {sorted(materials)}")
            for t in [tag] if tag is not None else list(materials):
                materials[t][c.field] = value
    return out


def engine_options(constants: Mapping[str, float], engine: str) -> dict[str, float]:
    """The profile's options of `engine` ({option: value})."""
    return {c.field: v for n, v in constants.items() if (c := constant(n)[0]).where == engine}


def apply_profile(morph: Morphology, constants: Mapping[str, float]) -> Morphology:
    """The morphology with the profile's spec and material constants (the same robot as a spec file holding
    them); the morphology itself without a profile."""
    if not constants:
        return morph
    return Morphology.from_dict(apply_to_spec(morph.to_dict(), constants))


def engine_only(constants: Mapping[str, float]) -> dict[str, float]:
    """The profile's engine constants alone: for a morphology the rest was already applied to."""
    return {n: v for n, v in constants.items() if constant(n)[0].where not in ("spec", *MATERIALS)}


def ground_friction(morph: Morphology, constants: Mapping[str, float]) -> float:
    """The robot's ground friction under the profile."""
    return float(constants.get("ground_friction", morph.ground_friction))


def current_value(morph: Morphology, name: str, engine: str, options: Mapping[str, object]) -> float:
    """A constant's value in this robot and engine setting (a material's without a tag: its first tag's)."""
    c, tag = constant(name)
    if c.where == "spec":
        return float(morph.to_dict()[c.field])
    if c.where in MATERIALS:
        materials = morph.to_dict()["structure"][MATERIALS[c.where]]
        return float(materials[tag if tag is not None else sorted(materials)[0]][c.field])
    from spinefarm.robot.engines import engine_spec

    return float(options.get(c.field, engine_spec(c.where).option(c.field).default)) if c.where == engine \
        else float(engine_spec(c.where).option(c.field).default)
