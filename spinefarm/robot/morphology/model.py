"""A morphology: a structure plus the controller and trial defaults that go with it."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field

from spinefarm.protocol.errors import ConfigError, MorphologySpecError, bounded, check_fields
from spinefarm.robot.morphology.structure import StructureSpec


@dataclass(frozen=True)
class ImpedanceGains:
    """T* = max(0, T0 + K (L - Lc) + B (v - V0)) (spec 4.2). Lc None means the start length."""

    tension_offset_n: float = bounded(0.0)
    position_gain_n_per_m: float = bounded(1000.0, 0.0)
    velocity_gain_n_s_per_m: float = bounded(100.0, 0.0)
    control_length_cm: float | None = bounded(None, 0.0, low_inclusive=False)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class ControlSpec:
    """How strings are controlled.

    cpg_tags: string tags that get one CPG node each (NTRT controller space), in creation order.
    impedance: per-tag gains for every impedance-controlled string (CPG strings and strings held
    with a zero velocity setpoint). Strings of other tags keep their rest length (or are driven,
    see StringMaterial.drive_offset_cm).
    cpg_update_period_s: NTRT's controlTime; the CPG output is held between updates.
    node_range: [lo, hi] of the NTRT node parameters (frequency and amplitude coefficients).
    """

    cpg_tags: tuple[str, ...]
    impedance: tuple[tuple[str, ImpedanceGains], ...]
    cpg_update_period_s: float = bounded(0.001, 0.0, 10.0, low_inclusive=False)
    node_range: tuple[float, float] = (0.0, 30.0)
    descending_command: float = 2.0
    amplitude_rate_per_s: float = 20.0

    def __post_init__(self) -> None:
        check_fields(self)
        if self.node_range[1] < self.node_range[0]:
            raise ConfigError("node_range is inverted", received=self.node_range, expected="lo <= hi")
        missing = [t for t in self.cpg_tags if t not in dict(self.impedance)]
        if missing:
            raise MorphologySpecError("CPG tags lack impedance gains", received=missing,
                                      expected="an impedance entry for every CPG tag")

    def gains(self, tag: str) -> ImpedanceGains | None:
        return dict(self.impedance).get(tag)


@dataclass(frozen=True)
class Morphology:
    """Everything a trial needs to know about a robot except the learned parameters."""

    name: str
    structure: StructureSpec
    control: ControlSpec
    scored_segment: int
    duration_s: float = bounded(30.0, 0.0, low_inclusive=False)
    ground_friction: float = bounded(0.5, 0.0, 10.0)
    controllers: tuple[str, ...] = ("ntrt",)
    description: str = ""
    extra: tuple[tuple[str, float], ...] = field(default=())

    def __post_init__(self) -> None:
        n = self.structure.n_segments
        if not 0 <= self.scored_segment < n:
            raise MorphologySpecError("scored_segment is not a segment", received=self.scored_segment,
                                      expected=f"an index in [0, {n - 1}]")
        check_fields(self)
        tags = {s.tag for s in self.structure.strings}
        unknown = [t for t, _ in self.control.impedance if t not in tags]
        if unknown:
            raise MorphologySpecError("impedance gains name string tags the structure lacks",
                                      received=unknown, expected=f"tags among {sorted(tags)}")

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "description": self.description,
            "structure": self.structure.to_dict(),
            "control": {
                "cpg_tags": list(self.control.cpg_tags),
                "impedance": {t: asdict(g) for t, g in self.control.impedance},
                "cpg_update_period_s": self.control.cpg_update_period_s,
                "node_range": list(self.control.node_range),
                "descending_command": self.control.descending_command,
                "amplitude_rate_per_s": self.control.amplitude_rate_per_s,
            },
            "scored_segment": self.scored_segment,
            "duration_s": self.duration_s,
            "ground_friction": self.ground_friction,
            "controllers": list(self.controllers),
            "extra": dict(self.extra),
        }

    @classmethod
    def from_dict(cls, d: Mapping) -> Morphology:
        try:
            c = d["control"]
            control = ControlSpec(
                cpg_tags=tuple(c["cpg_tags"]),
                impedance=tuple(sorted((t, ImpedanceGains(**g)) for t, g in c["impedance"].items())),
                cpg_update_period_s=float(c["cpg_update_period_s"]),
                node_range=(float(c["node_range"][0]), float(c["node_range"][1])),
                descending_command=float(c.get("descending_command", 2.0)),
                amplitude_rate_per_s=float(c.get("amplitude_rate_per_s", 20.0)),
            )
            return cls(
                name=str(d["name"]), structure=StructureSpec.from_dict(d["structure"]), control=control,
                scored_segment=int(d["scored_segment"]), duration_s=float(d["duration_s"]),
                ground_friction=float(d["ground_friction"]), controllers=tuple(d["controllers"]),
                description=str(d.get("description", "")),
                extra=tuple(sorted((str(k), float(v)) for k, v in dict(d.get("extra", {})).items())),
            )
        except (KeyError, TypeError) as exc:
            raise MorphologySpecError("morphology dict is malformed", received=repr(exc),
                                      expected="the keys written by Morphology.to_dict") from exc

    def spec_hash(self) -> str:
        blob = json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(blob.encode()).hexdigest()[:16]

    def joint_of_string(self) -> list[int]:
        """Joint index of each string: the lower of its two segment indices (segments form a chain)."""
        seg = self.structure.node_segment
        return [min(seg[s.a], seg[s.b]) for s in self.structure.strings]
