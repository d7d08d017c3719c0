"""Shared pieces of the coordinator tests: a clock tests move by hand, a small sphere run."""

from __future__ import annotations

from coordinator.problem import build_run_config
from coordinator.setup import SearchSettings, new_run


class FakeClock:
    def __init__(self, t: float = 100.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t

    def advance(self, dt: float) -> None:
        self.t += dt


def sphere_core(trials: int = 20, *, lease_s: float = 10.0, clock=None, out=None, seed: int = 3,
                startup_trials: int | None = None, morphology: str = "sphere:4", run_id: str = "test-run"):
    clock = clock or FakeClock()
    config = build_run_config(run_id, morphology, seed=seed)
    core, storage = new_run(config, SearchSettings(trials=trials, lease_s=lease_s,
                                                   startup_trials=startup_trials), out, clock)
    return core, storage, clock
