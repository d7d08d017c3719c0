"""How one trial runs, as data: duration, step, engine and its options, motor model, CPG timing,
guards, recording and scene. Engine-neutral: a coordinator builds and hashes it without a simulator."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from typing import Any

from spinefarm.protocol.errors import ConfigError, bounded, check_fields
from spinefarm.robot.engines import DEFAULT_ENGINE, check_engine_options, engine_spec
from spinefarm.robot.profile import check_constants, engine_options, profile_hash
from spinefarm.robot.scene import SceneConfig

MOTOR_MODEL_NAMES = ("physical", "ntrt2014", "ntrt2026")
MAX_DURATION_S = 3600.0  # the longest trial a config takes


@dataclass(frozen=True)
class TrialConfig:
    """How to run one trial. None means "the morphology's default".

    dt_s: the physics step; None means the engine's default (robot.engines: the largest step whose median
    distance error on the 12-segment Tetraspine stays within max(1 %, chaos floor) of the converged reference,
    docs/accuracy.md; `step_s` resolves it).
    engine: a registered physics backend (robot.engines: "bullet", "mujoco"); engine_options: that backend's
    own settings (solver iterations, friction anchors, contact parameters), checked against the registry here.
    motor_model: "physical" (limits in cm/s and cm/s^2, independent of dt) or "ntrt2014" (NTRT's
    per-step caps, only faithful at dt = 1 ms, for replaying published gaits) or "ntrt2026" (NTRT's current
    motor, V dt per step and no acceleration limit, the one its recordings were made with).
    cpg_update_period_s: NTRT's controlTime (CPG output held in between).
    cpg_max_step_s: the CPG's RK4 sub-step cap; None: 1 ms, longer for a network slow enough
    (worker.control.cpg.CpgIntegrator).
    cpg_step_s: the longest own step of the CPG where the morphology updates it every physics step
    (controlTime <= dt): each network updates at the largest multiple of the physics step within this and 0.25
    over its fastest rate, by one RK4 step one update ahead, the setpoints in between interpolated linearly
    (exact at the updates; worker.control.law); None: the engine's default (robot.engines: every physics step on
    the Bullet judge, at most 4 ms on MuJoCo, docs/performance.md); 0: every physics step. A controlTime above
    the physics step (NTRT's 0.1 s) or given here is kept as it is.
    settle_s: seconds simulated before locomotion with the CPG held at rest (zero output, the impedance
    reflex holding the posture); distance, speed, work and COT count from the pose at its end,
    NTRT's distance (ntrt_distance_cm) still from the start. 0: scored from the start.
    pose_jitter_cm: seeded Gaussian offset of every segment's start position (0: the seed is unused).
    profile: named physical constants laid over the robot and the engine (robot.profile, `--profile FILE`);
    carried with the config so that every worker applies them.
    auto_dt: use min(dt_s, dt_safety_factor * the string network's stable-step estimate).
    refuse_unstable_dt: raise ConfigError for a dt_s above that estimate (known to be unstable).
    """

    duration_s: float | None = bounded(None, 0.0, MAX_DURATION_S, low_inclusive=False)
    settle_s: float = bounded(0.0, 0.0, 60.0)
    dt_s: float | None = bounded(None, 1e-6, 0.02)
    auto_dt: bool = False
    dt_safety_factor: float = bounded(0.5, 0.0, 1.0, low_inclusive=False)
    refuse_unstable_dt: bool = True
    engine: str = DEFAULT_ENGINE
    engine_options: dict[str, Any] = field(default_factory=dict)
    motor_model: str = "physical"
    controller: str | None = None
    cpg_update_period_s: float | None = bounded(None, 1e-6, 10.0)
    cpg_max_step_s: float | None = bounded(None, 1e-6, 0.1)
    cpg_step_s: float | None = bounded(None, 0.0, 0.1)
    relocate_anchors: bool = True
    pose_jitter_cm: float = bounded(0.0, 0.0, 10.0)
    ground_friction: float | None = bounded(None, 0.0, 10.0)
    check_every_s: float = bounded(0.01, 1e-6, 10.0)
    max_body_speed_m_s: float = bounded(5.0, 0.0, low_inclusive=False)
    min_height_m: float = -0.5
    max_height_m: float = 5.0
    max_stretch_ratio: float = bounded(4.0, 1.0, low_inclusive=False)
    max_kinetic_energy_j: float = bounded(200.0, 0.0, low_inclusive=False)
    record_every_s: float | None = bounded(None, 1e-6, 10.0)
    scene: SceneConfig = field(default_factory=SceneConfig)
    extras: dict[str, float] = field(default_factory=dict)
    profile: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        check_fields(self)
        object.__setattr__(self, "profile", check_constants(self.profile))
        twice = sorted(set(engine_options(self.profile, self.engine)) & set(self.engine_options or {}))
        if twice:
            raise ConfigError("an engine option is set by both the profile and engine_options", received=twice,
                              expected="each option in one of them")
        if not isinstance(self.engine_options, Mapping):
            raise ConfigError("engine_options is not a mapping", received=self.engine_options,
                              expected="{option: value} of the engine's settings")
        object.__setattr__(self, "engine_options", dict(self.engine_options))
        check_engine_options(self.engine, self.engine_options)
        if self.motor_model not in MOTOR_MODEL_NAMES:
            raise ConfigError("unknown motor_model", received=self.motor_model, expected=sorted(MOTOR_MODEL_NAMES))
        if isinstance(self.scene, Mapping):
            object.__setattr__(self, "scene", SceneConfig.from_dict(dict(self.scene)))
        if not isinstance(self.scene, SceneConfig):
            raise ConfigError("scene is not a scene config", received=type(self.scene).__name__,
                              expected="a SceneConfig or its dict")

    @property
    def step_s(self) -> float:
        """The physics step asked for: dt_s, or the engine's default."""
        return self.dt_s if self.dt_s is not None else engine_spec(self.engine).default_dt_s

    @property
    def cpg_own_step_s(self) -> float | None:
        """The CPG's own step asked for (None: every physics step): cpg_step_s, or the engine's default."""
        own = self.cpg_step_s if self.cpg_step_s is not None else engine_spec(self.engine).default_cpg_step_s
        return own or None

    def to_dict(self) -> dict:
        """Every field, and with a profile its hash (robot.profile.profile_hash), kept in run files; no profile
        keys without a profile and no cpg_step_s when unset (so configs from before them keep their hash)."""
        d = {**asdict(self), "scene": self.scene.to_dict()}
        if self.profile:
            d["profile_hash"] = profile_hash(self.profile)
        else:
            del d["profile"]
        if d["cpg_step_s"] is None:
            del d["cpg_step_s"]
        return d

    @classmethod
    def from_dict(cls, d: Mapping) -> TrialConfig:
        d = {k: v for k, v in d.items() if k != "profile_hash"}  # derived from the profile: to_dict writes it anew
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ConfigError("unknown trial config fields", received=unknown, expected=sorted(known))
        return cls(**d)

    def config_hash(self) -> str:
        blob = json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(blob.encode()).hexdigest()[:16]
