"""How `search --engine auto` chose a run's tier, typed and stored with the run's settings.

The calibration (worker.tools.calibrate) runs the robot's gaits on both tiers; its figures and decision are
kept here so a resumed run keeps its tier and the report, the API and the dashboard can show why.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from spinefarm.protocol.errors import ConfigError

TIERS = ("mujoco", "bullet")


@dataclass(frozen=True)
class EngineChoice:
    """engine: the tier chosen (mujoco screens, else bullet); mode: "auto"; cached: the calibration came
    from the cache or the package; shipped: from the package (robot/calibrations, made by
    bench/ship_calibrations.py); screen_fit: what fitting the screen to the judge did when the unfitted screen
    failed (worker.tools.screen_fit: its decision, the fitted profile and its hash, the figures before and after),
    None when no fit ran; rungs_added: the screening rungs auto added ("S,S", None: none added), eta_added its
    eta and ladder_reason why that ladder (the robot's own or the default, cli.engine_auto.screen_ladder); spearman,
    top_overlap of top_k, median_distance_ratio (MuJoCo/Bullet over n_moving gaits that move): the
    agreement; n_random, n_bests: the gaits compared; spec_hash: the robot calibrated; reason: the decision
    in words; tiers: {tier: {cpu_s_per_sim_s, step_error}}."""

    engine: str
    mode: str = "auto"
    cached: bool = False
    shipped: bool = False
    screen_fit: dict[str, Any] | None = None
    rungs_added: str | None = None
    eta_added: int | None = None
    ladder_reason: str = ""
    spearman: float | None = None
    top_overlap: int = 0
    top_k: int = 0
    median_distance_ratio: float | None = None
    n_moving: int = 0
    n_random: int = 0
    n_bests: int = 0
    spec_hash: str = ""
    reason: str = ""
    tiers: dict[str, dict[str, float | None]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.engine not in TIERS:
            raise ConfigError("engine choice names an unknown tier", received=self.engine, expected=list(TIERS))
        if self.mode != "auto":
            raise ConfigError("engine choice mode", received=self.mode, expected="auto")
        for name in ("top_overlap", "top_k", "n_moving", "n_random", "n_bests"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ConfigError(f"engine choice {name} is not a count", received=value, expected="an integer >= 0")
        if not isinstance(self.tiers, dict):
            raise ConfigError("engine choice tiers is not an object", received=self.tiers,
                              expected="{tier: {cpu_s_per_sim_s, step_error}}")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: Any) -> EngineChoice:
        if not isinstance(d, dict):
            raise ConfigError("engine choice is not an object", received=type(d).__name__, expected="a JSON object")
        names = set(cls.__dataclass_fields__)
        unknown = sorted(set(d) - names)
        if unknown:
            raise ConfigError("engine choice has unknown fields", received=unknown, expected=sorted(names))
        return cls(**d)

    @classmethod
    def from_calibration(cls, result: dict[str, Any], cached: bool, rungs_added: str | None,
                         eta_added: int | None = None, ladder_reason: str = "") -> EngineChoice:
        """The choice a calibration result (worker.tools.calibrate.calibration) makes."""
        tiers = {t: {k: v.get(k) for k in ("cpu_s_per_sim_s", "step_error")}
                 for t, v in (result.get("tiers") or {}).items()}
        return cls(engine=result["decision"], cached=cached, shipped=bool(result.get("shipped")),
                   screen_fit=result.get("screen_fit"), rungs_added=rungs_added, eta_added=eta_added,
                   ladder_reason=ladder_reason,
                   spearman=result.get("spearman"), top_overlap=int(result.get("top_overlap") or 0),
                   top_k=int(result.get("top_k") or 0), median_distance_ratio=result.get("median_distance_ratio"),
                   n_moving=int(result.get("n_moving") or 0), n_random=int(result.get("n_random") or 0),
                   n_bests=int(result.get("n_bests") or 0), spec_hash=str(result.get("spec_hash") or ""),
                   reason=str(result.get("reason") or ""), tiers=tiers)

    def describe(self) -> str:
        """One line for the search's report."""
        rho = "-" if self.spearman is None else f"{self.spearman:.3f}"
        ratio = "-" if self.median_distance_ratio is None else f"{self.median_distance_ratio:.3f}"
        # by name: a run file stores the tiers with sorted keys, so a resumed run says it in the same order
        cost = ", ".join(f"{t} {v['cpu_s_per_sim_s']:.3f}" for t, v in sorted(self.tiers.items())
                         if v.get("cpu_s_per_sim_s") is not None)
        return (f"engine auto chose {self.engine}: Spearman rho {rho}, top-{self.top_k} overlap {self.top_overlap}, "
                f"median distance ratio {ratio} (MuJoCo/Bullet, {self.n_moving} gaits that move); "
                f"CPU s per simulated s {cost}"
                + (f"; rungs {self.rungs_added}" if self.rungs_added else "")
                + (f" eta {self.eta_added}" if self.rungs_added and self.eta_added else "")
                + (f" ({self.ladder_reason})" if self.rungs_added and self.ladder_reason else "")
                + (" [shipped calibration]" if self.shipped else " [calibration cached]" if self.cached else "")
                + ("" if self.screen_fit is None else f"\n  {self.screen_fit.get('summary', '')}"))
