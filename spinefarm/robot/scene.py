"""Scenes as data: flat ground, slope, rough ground, obstacles; and which contacts they need.

Pure geometry (no engine): each engine (worker/engines/bullet.py, mujoco_model.py) turns a Terrain into
bodies. Y is up; the flat ground's top is at y = 0.5 cm (NTRT 2014).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from spinefarm.protocol.errors import ConfigError, bounded, check_fields

GROUND_TOP_CM = 0.5
GROUND_HALF_EXTENT_CM = 500.0
GROUND_HALF_HEIGHT_CM = 0.5
FILTERS = ("auto", "all", "neighbours")


@dataclass(frozen=True)
class SceneConfig:
    """What the robot stands on.

    kind: flat | slope (plane tilted by slope_deg about +X, rising toward -z) | rough (seeded
    heightfield of rough_amplitude_cm with rough_wavelength_cm) | obstacles (flat ground with bars
    across z of obstacle_height_cm x obstacle_depth_cm every obstacle_spacing_cm).
    ground_half_extent_cm: the ground's half width in x and z (NTRT's box: 500 cm, a 10 m square); a gait
    fast enough to reach its edge within a trial falls off it, so longer or faster trials need a larger one.
    collision_filter: "all" (every segment pair may collide, as NTRT), "neighbours" (each segment
    touches only the terrain and its neighbours in the chain), "auto" (neighbours on flat ground
    and slopes, all pairs on rough ground and obstacles).
    """

    kind: str = "flat"
    friction: float | None = bounded(None, 0.0, 10.0)
    slope_deg: float = bounded(0.0, -45.0, 45.0)
    rough_amplitude_cm: float = bounded(2.0, 0.0, 50.0)
    rough_wavelength_cm: float = bounded(40.0, 2.0, 1000.0)
    rough_seed: int = 0
    obstacle_height_cm: float = bounded(3.0, 0.0, 100.0, low_inclusive=False)
    obstacle_depth_cm: float = bounded(5.0, 0.0, 200.0, low_inclusive=False)
    obstacle_spacing_cm: float = bounded(60.0, 1.0, 1000.0)
    collision_filter: str = "all"
    ground_half_extent_cm: float = bounded(GROUND_HALF_EXTENT_CM, 10.0, 1e5)

    def __post_init__(self) -> None:
        if self.kind not in SCENE_BUILDERS:
            raise ConfigError("unknown scene kind", received=self.kind, expected=sorted(SCENE_BUILDERS))
        if self.collision_filter not in FILTERS:
            raise ConfigError("unknown collision_filter", received=self.collision_filter, expected=list(FILTERS))
        check_fields(self, "scene.")

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        if d["ground_half_extent_cm"] == GROUND_HALF_EXTENT_CM:  # NTRT's: left out, as before the field was
            del d["ground_half_extent_cm"]                      # (stored configs and their hashes unchanged)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> SceneConfig:
        unknown = sorted(set(d) - set(cls.__dataclass_fields__))
        if unknown:
            raise ConfigError("unknown scene fields", received=unknown, expected=sorted(cls.__dataclass_fields__))
        return cls(**d)


def parse_scene(text: str) -> dict[str, Any]:
    """A scene from the command line: "rough", "slope,slope_deg=10" or "rough,rough_amplitude_cm=3,
    collision_filter=auto" (kind first, then field=value pairs), validated as a SceneConfig."""
    parts = [p.strip() for p in text.split(",") if p.strip()]
    if not parts:
        raise ConfigError("empty scene", received=text, expected=f"a kind ({', '.join(sorted(SCENE_BUILDERS))}) "
                          "optionally followed by ,field=value pairs")
    out: dict[str, Any] = {}
    if "=" not in parts[0]:
        out["kind"] = parts.pop(0)
    fields = SceneConfig.__dataclass_fields__
    for p in parts:
        key, sep, value = p.partition("=")
        key = key.strip()
        if not sep or key not in fields:
            raise ConfigError("bad scene field", received=p, expected=f"field=value with field in {sorted(fields)}")
        value = value.strip()
        if key in ("kind", "collision_filter"):
            out[key] = value
        elif key == "rough_seed":
            try:
                out[key] = int(value)
            except ValueError as exc:
                raise ConfigError("scene.rough_seed is not an integer", received=value, expected="an integer") from exc
        else:
            try:
                out[key] = float(value)
            except ValueError as exc:
                raise ConfigError(f"scene.{key} is not a number", received=value, expected="a number") from exc
    return SceneConfig.from_dict(out).to_dict()


@dataclass(frozen=True)
class Box:
    centre_cm: tuple[float, float, float]
    half_extents_cm: tuple[float, float, float]
    quaternion: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)


@dataclass(frozen=True)
class Heightfield:
    """heights_cm (n_rows, n_cols) on a grid of spacing_cm centred at the origin; row index runs
    along z, column index along x; surface y = GROUND_TOP_CM + height."""

    heights_cm: np.ndarray
    spacing_cm: float


@dataclass(frozen=True)
class Terrain:
    friction: float
    boxes: tuple[Box, ...] = ()
    heightfield: Heightfield | None = None
    pairs: str = "all"  # resolved collision filter: "all" or "neighbours"
    notes: dict[str, float] = field(default_factory=dict)


_sin_each = np.frompyfunc(math.sin, 1, 1)


def _glibc_sin(x: np.ndarray) -> np.ndarray:
    """glibc's sine element by element: numpy's own vectorised sine (AVX-512 CPUs) differs in the last bit."""
    return _sin_each(x).astype(np.float64)


def _rough_heights(cfg: SceneConfig) -> Heightfield:
    spacing = cfg.rough_wavelength_cm / 8.0
    n = int(2 * cfg.ground_half_extent_cm / spacing) + 1
    coords = (np.arange(n) - (n - 1) / 2) * spacing
    x, z = np.meshgrid(coords, coords)  # rows along z, columns along x
    rng = np.random.default_rng(cfg.rough_seed)
    h = np.zeros_like(x)
    waves = 6
    for _ in range(waves):  # a sum of plane waves of one wavelength in random directions and phases
        angle = rng.uniform(0, math.pi)
        phase = rng.uniform(0, 2 * math.pi)
        h += _glibc_sin(2 * math.pi / cfg.rough_wavelength_cm * (x * math.cos(angle) + z * math.sin(angle)) + phase)
    h *= cfg.rough_amplitude_cm / max(np.abs(h).max(), 1e-12)
    return Heightfield(h, spacing)


TerrainBuilder = Callable[[SceneConfig, float, str, tuple[float, float]], "Terrain"]
# kind -> builder(config, friction, collision pairs, robot's z extent at the start): the scene kinds
SCENE_BUILDERS: dict[str, TerrainBuilder] = {}


def scene_kind(name: str, filter_auto: str) -> Callable[[TerrainBuilder], TerrainBuilder]:
    """Register a terrain builder as scene kind `name`; filter_auto is what collision_filter "auto"
    means on it ("neighbours" where segments cannot meet, "all" where the ground can fold them)."""
    def register(fn: TerrainBuilder) -> TerrainBuilder:
        SCENE_BUILDERS[name] = fn
        _AUTO_FILTER[name] = filter_auto
        return fn
    return register


_AUTO_FILTER: dict[str, str] = {}


def _half(cfg: SceneConfig) -> tuple[float, float, float]:
    return (cfg.ground_half_extent_cm, GROUND_HALF_HEIGHT_CM, cfg.ground_half_extent_cm)


def _flat_box(cfg: SceneConfig) -> Box:
    return Box((0.0, GROUND_TOP_CM - GROUND_HALF_HEIGHT_CM, 0.0), _half(cfg))


@scene_kind("flat", "neighbours")
def _flat(cfg: SceneConfig, friction: float, pairs: str, extent_z: tuple[float, float]) -> Terrain:
    return Terrain(friction, (_flat_box(cfg),), pairs=pairs)


@scene_kind("slope", "neighbours")
def _slope(cfg: SceneConfig, friction: float, pairs: str, extent_z: tuple[float, float]) -> Terrain:
    a = math.radians(cfg.slope_deg)
    # rotation about +X by a: the plane rises toward -z for a > 0 and passes through (0, 0.5, 0)
    quat = (math.sin(a / 2), 0.0, 0.0, math.cos(a / 2))
    centre = (0.0, GROUND_TOP_CM - GROUND_HALF_HEIGHT_CM * math.cos(a), -GROUND_HALF_HEIGHT_CM * math.sin(a))
    return Terrain(friction, (Box(centre, _half(cfg), quat),), pairs=pairs)


@scene_kind("rough", "all")
def _rough(cfg: SceneConfig, friction: float, pairs: str, extent_z: tuple[float, float]) -> Terrain:
    return Terrain(friction, (), heightfield=_rough_heights(cfg), pairs=pairs)


@scene_kind("obstacles", "all")
def _obstacles(cfg: SceneConfig, friction: float, pairs: str, extent_z: tuple[float, float]) -> Terrain:
    """Bars across the whole width, placed outside the robot's start extent."""
    z_lo, z_hi = extent_z
    bars = []
    hy, hz = cfg.obstacle_height_cm / 2, cfg.obstacle_depth_cm / 2
    edge = cfg.ground_half_extent_cm
    z = z_hi + cfg.obstacle_spacing_cm / 2
    while z < edge:
        bars.append(Box((0.0, GROUND_TOP_CM + hy, z), (edge, hy, hz)))
        z += cfg.obstacle_spacing_cm
    z = z_lo - cfg.obstacle_spacing_cm / 2
    while z > -edge:
        bars.append(Box((0.0, GROUND_TOP_CM + hy, z), (edge, hy, hz)))
        z -= cfg.obstacle_spacing_cm
    return Terrain(friction, (_flat_box(cfg), *bars), pairs=pairs)


def build_terrain(cfg: SceneConfig, default_friction: float, robot_extent_z_cm: tuple[float, float]) -> Terrain:
    """Boxes and heightfield of a scene; robot_extent_z_cm keeps obstacles clear of the start pose."""
    friction = default_friction if cfg.friction is None else cfg.friction
    pairs = _AUTO_FILTER[cfg.kind] if cfg.collision_filter == "auto" else cfg.collision_filter
    return SCENE_BUILDERS[cfg.kind](cfg, friction, pairs, robot_extent_z_cm)


def surface_height_cm(terrain: Terrain, x_cm: np.ndarray, z_cm: np.ndarray) -> np.ndarray:
    """Top of the terrain (y, cm) under points (x, z): used to lift the start pose clear of it."""
    x = np.asarray(x_cm, dtype=float)
    z = np.asarray(z_cm, dtype=float)
    y = np.full(np.broadcast(x, z).shape, -np.inf)
    if terrain.heightfield is not None:
        hf = terrain.heightfield
        n_rows, n_cols = hf.heights_cm.shape
        c = np.clip(np.rint(x / hf.spacing_cm + (n_cols - 1) / 2).astype(int), 0, n_cols - 1)
        r = np.clip(np.rint(z / hf.spacing_cm + (n_rows - 1) / 2).astype(int), 0, n_rows - 1)
        # the max over the neighbouring grid points bounds the interpolated surface
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                rr = np.clip(r + dr, 0, n_rows - 1)
                cc = np.clip(c + dc, 0, n_cols - 1)
                y = np.maximum(y, GROUND_TOP_CM + hf.heights_cm[rr, cc])
    for box in terrain.boxes:
        qx, _, _, qw = box.quaternion
        a = 2 * math.atan2(qx, qw)
        if abs(a) > 1e-12:  # the tilted plane (slope)
            y = np.maximum(y, GROUND_TOP_CM - z * math.tan(a))
            continue
        cx, cy, cz = box.centre_cm
        hx, hy, hz = box.half_extents_cm
        inside = (np.abs(x - cx) <= hx) & (np.abs(z - cz) <= hz)
        y = np.where(inside, np.maximum(y, cy + hy), y)
    return y


def pairs_off(terrain: Terrain, n_segments: int) -> list[tuple[int, int]]:
    """Segment pairs whose collisions are switched off."""
    if terrain.pairs != "neighbours":
        return []
    return [(i, j) for i in range(n_segments) for j in range(i + 2, n_segments)]


@dataclass(frozen=True)
class GroundSpec:
    """Flat static box whose top is at top_y_cm (NTRT [P]: half-height 0.5, top at y = 0.5)."""

    top_y_cm: float = bounded(GROUND_TOP_CM)
    half_extent_cm: float = bounded(GROUND_HALF_EXTENT_CM, 0.0, low_inclusive=False)
    half_height_cm: float = bounded(GROUND_HALF_HEIGHT_CM, 0.0, low_inclusive=False)
    friction: float = bounded(0.5, 0.0, 10.0)

    def __post_init__(self) -> None:
        check_fields(self, "ground.")

    def to_terrain(self) -> Terrain:
        box = Box((0.0, self.top_y_cm - self.half_height_cm, 0.0),
                  (self.half_extent_cm, self.half_height_cm, self.half_extent_cm))
        return Terrain(self.friction, (box,))
