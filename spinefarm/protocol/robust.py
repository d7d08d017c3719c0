"""Robust scoring as data: K episodes per parameter set, each in its own randomised world, scored by a
statistic over them (`--episodes K --randomize ... --robust mean|q25|min`).

Engine-free (numpy and the standard library): the coordinator stores and reduces, the worker draws and
runs. Episode k of a trial is seeded from the trial's seed and k alone, so the same trial gives the same
K worlds on every worker, in every process, after every resume.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from spinefarm.protocol.errors import ConfigError, MessageError
from spinefarm.protocol.measured import MEASURED_NUMBERS, Measured

STATISTICS = ("mean", "q25", "min")
SCENES = ("flat", "rough")
# name -> (low, high, what it means): the ranges --randomize accepts
RANDOMIZE_RANGES: dict[str, tuple[float, float, str]] = {
    "friction": (0.0, 0.9, "ground friction x (1 + U(-f, f))"),
    "mass": (0.0, 0.9, "every rod's density x (1 + U(-m, m))"),
    "start_jitter_cm": (0.0, 10.0, "Gaussian offset of every segment's start position, cm"),
}
RANDOMIZE_KEYS = (*RANDOMIZE_RANGES, "scene")
MAX_EPISODES = 256
_ALLOWED = ("friction=F (0..0.9), mass=M (0..0.9), start_jitter_cm=J (0..10), scene=flat|rough, "
            "comma-separated, e.g. friction=0.1,mass=0.05,start_jitter_cm=0.5,scene=rough")


def parse_randomize(text: str) -> dict[str, Any]:
    """`friction=0.1,mass=0.05,start_jitter_cm=0.5,scene=rough` -> {name: value}; ConfigError names the
    offending item and what is allowed."""
    if not isinstance(text, str) or not text.strip():
        raise ConfigError("--randomize is empty", received=text, expected=_ALLOWED)
    out: dict[str, Any] = {}
    for item in text.split(","):
        key, sep, raw = (s.strip() for s in item.partition("="))
        if not sep or not key:
            raise ConfigError("--randomize item is not NAME=VALUE", received=item, expected=_ALLOWED)
        if key not in RANDOMIZE_KEYS:
            raise ConfigError(f"--randomize has an unknown name {key!r}", received=item, expected=_ALLOWED)
        if key in out:
            raise ConfigError(f"--randomize names {key!r} twice", received=text, expected="each name at most once")
        out[key] = _value(key, raw, item)
    return out


def _value(key: str, raw: str, item: str) -> Any:
    if key == "scene":
        if raw not in SCENES:
            raise ConfigError("--randomize scene is not a randomisable scene", received=item,
                              expected=f"scene={'|'.join(SCENES)}")
        return raw
    low, high, _ = RANDOMIZE_RANGES[key]
    try:
        value = float(raw)
    except ValueError:
        raise ConfigError(f"--randomize {key} is not a number", received=item,
                          expected=f"{key}=a number in [{low:g}, {high:g}]") from None
    if not (math.isfinite(value) and low <= value <= high):
        raise ConfigError(f"--randomize {key} out of range", received=item,
                          expected=f"{key}=a number in [{low:g}, {high:g}]")
    return value


def check_randomize(d: Any) -> dict[str, Any]:
    """A stored randomisation (a dict) checked like the command line's."""
    if not isinstance(d, dict):
        raise ConfigError("randomize is not a mapping", received=d, expected=_ALLOWED)
    for key, value in d.items():
        if key not in RANDOMIZE_KEYS:
            raise ConfigError(f"randomize has an unknown name {key!r}", received=key, expected=_ALLOWED)
        _value(key, str(value), f"{key}={value}")
    return dict(d)


@dataclass(frozen=True)
class RobustSpec:
    """episodes: K worlds per parameter set; randomize: what each world draws (parse_randomize);
    statistic: how the per-episode objectives become the trial's (mean, q25: the 25th percentile, min).
    rung_episodes, rung_durations_s: in a multi-fidelity run, K of each rung (by its duration); `episodes`
    is then the last rung's."""

    episodes: int = 1
    randomize: dict[str, Any] = field(default_factory=dict)
    statistic: str = "mean"
    rung_episodes: tuple[int, ...] = ()
    rung_durations_s: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "rung_episodes", tuple(self.rung_episodes))
        object.__setattr__(self, "rung_durations_s", tuple(float(d) for d in self.rung_durations_s))
        for k in (self.episodes, *self.rung_episodes):
            if isinstance(k, bool) or not isinstance(k, int) or not 1 <= k <= MAX_EPISODES:
                raise ConfigError("--episodes out of range", received=k, expected=f"an integer in [1, {MAX_EPISODES}]")
        if len(self.rung_episodes) != len(self.rung_durations_s) or \
                (self.rung_episodes and self.rung_episodes[-1] != self.episodes):
            raise ConfigError("--episodes per rung do not match the rungs", received=self.rung_episodes,
                              expected=f"one K per rung ({len(self.rung_durations_s)}), the last = episodes")
        object.__setattr__(self, "randomize", check_randomize(self.randomize))
        if self.statistic not in STATISTICS:
            raise ConfigError("--robust is not a statistic", received=self.statistic, expected="|".join(STATISTICS))

    @property
    def active(self) -> bool:
        return self.episodes > 1 or bool(self.randomize)

    def episodes_for(self, duration_s: float | None) -> int:
        """K of the rung whose trials last `duration_s` (None or not a rung's: `episodes`)."""
        if duration_s is not None and float(duration_s) in self.rung_durations_s:
            return self.rung_episodes[self.rung_durations_s.index(float(duration_s))]
        return self.episodes

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        if not self.rung_episodes:  # a run without rungs stores only what it uses
            del d["rung_episodes"], d["rung_durations_s"]
        else:
            d["rung_episodes"], d["rung_durations_s"] = list(self.rung_episodes), list(self.rung_durations_s)
        return d

    @classmethod
    def from_dict(cls, d: Any) -> RobustSpec:
        if not d:
            return cls()
        if not isinstance(d, dict) or not set(d) <= set(cls.__dataclass_fields__):
            raise ConfigError("robust settings are malformed", received=d,
                              expected="{episodes, randomize, statistic}")
        return cls(**d)


@dataclass(frozen=True)
class EpisodeDraw:
    """One episode's world: its seed (start jitter, the rough ground), friction and mass factors."""

    episode: int
    seed: int
    friction_scale: float = 1.0
    mass_scale: float = 1.0
    start_jitter_cm: float = 0.0
    rough_seed: int = -1   # -1: the run's own scene


def episode_seed(trial_seed: int, episode: int) -> int:
    """The seed of episode k of a trial: from (trial seed, k) alone, in [0, 2^31 - 1)."""
    return int(np.random.SeedSequence([int(trial_seed), int(episode)]).generate_state(1)[0] % (2**31 - 1))


def draw_episode(spec: RobustSpec, trial_seed: int, episode: int) -> EpisodeDraw:
    """Episode k's draw (every factor drawn, used or not, so adding one never changes the others)."""
    seed = episode_seed(trial_seed, episode)
    u = np.random.default_rng(seed).uniform(-1.0, 1.0, 3)
    r = spec.randomize
    return EpisodeDraw(episode, seed,
                       friction_scale=1.0 + float(r.get("friction", 0.0)) * float(u[0]),
                       mass_scale=1.0 + float(r.get("mass", 0.0)) * float(u[1]),
                       start_jitter_cm=float(r.get("start_jitter_cm", 0.0)),
                       rough_seed=seed if r.get("scene") == "rough" else -1)


def statistic(values: Any, name: str) -> float:
    """mean, q25 (numpy's linear 25th percentile) or min of finite values; NaN if none is finite."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return math.nan
    if name == "mean":
        return float(v.mean())
    if name == "q25":
        return float(np.percentile(v, 25.0))
    if name == "min":
        return float(v.min())
    raise ConfigError("unknown robust statistic", received=name, expected="|".join(STATISTICS))


# --- one episode's result on the wire ---------------------------------------------------------------
EPISODE_NUMBERS = (*MEASURED_NUMBERS, "friction_scale", "mass_scale", "start_jitter_cm")


@dataclass(frozen=True)
class EpisodeKey:
    """Which episode (k) and its seed: an episode result's first fields."""

    episode: int
    seed: int


@dataclass(frozen=True)
class EpisodeResult(Measured, EpisodeKey):
    """What one episode measured, with its draw: fields episode, seed (EpisodeKey), then what was measured
    (Measured: status complete | failed, reason as a trial's, the score parts), then the draw."""

    friction_scale: float
    mass_scale: float
    start_jitter_cm: float
    rough_seed: int

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: Any) -> EpisodeResult:
        names = [f for f in cls.__dataclass_fields__]
        if not isinstance(d, dict) or set(d) != set(names):
            raise MessageError("episode result is malformed", received=sorted(d) if isinstance(d, dict)
                               else type(d).__name__, expected=names)
        for k in ("episode", "seed", "rough_seed"):
            if isinstance(d[k], bool) or not isinstance(d[k], int):
                raise MessageError(f"episode result field {k!r} is not an integer", received=d[k],
                                   expected="an integer")
        for k in EPISODE_NUMBERS:
            if isinstance(d[k], bool) or not isinstance(d[k], int | float):
                raise MessageError(f"episode result field {k!r} is not a number", received=d[k], expected="a number")
        if d["status"] not in ("complete", "failed") or not isinstance(d["reason"], str) or len(d["reason"]) > 160:
            raise MessageError("episode result has a bad status or reason",
                               received=(d["status"], str(d["reason"])[:40]),
                               expected="status complete|failed and a reason of at most 160 characters")
        return cls(**{k: (float(d[k]) if k in EPISODE_NUMBERS else d[k]) for k in names})
