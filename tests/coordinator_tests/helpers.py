"""Shared pieces of the coordinator tests: a clock tests move by hand, a small sphere run, what a scheduler has
queued, a halving ladder."""

from __future__ import annotations

from spinefarm.coordinator.ladder.rungs import HalvingTrialScheduler
from spinefarm.coordinator.problem import build_run_config
from spinefarm.coordinator.scheduler import Scheduler
from spinefarm.coordinator.setup import SearchSettings, new_run
from spinefarm.protocol.settings import Rung, RunSettings


class FakeClock:
    def __init__(self, t: float = 100.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t

    def advance(self, dt: float) -> None:
        self.t += dt


def queued_keys(leases: Scheduler) -> list[int]:
    """The keys a scheduler has queued, in the order it issues them (its queue, read as it is)."""
    return list(leases._queue)


def halving_ladder(durations_s: tuple[float, ...], eta: int) -> HalvingTrialScheduler:
    """Successive halving over rungs of these simulated seconds, keeping 1/eta of each, as a run stores it."""
    return HalvingTrialScheduler(RunSettings(scheduler="halving", ladder=tuple(Rung(duration_s=d) for d in durations_s),
                                             eta=eta))


def sphere_core(trials: int = 20, *, lease_s: float = 10.0, clock=None, out=None, seed: int = 3,
                startup_trials: int | None = None, morphology: str = "sphere:4", run_id: str = "test-run",
                duration_s: float | None = None):
    """duration_s: wall time each test-objective trial takes on the worker."""
    clock = clock or FakeClock()
    config = build_run_config(run_id, morphology, seed=seed, duration_s=duration_s)
    # the paper's sampler: these tests check its phases and parents
    core, storage = new_run(config, SearchSettings(trials=trials, lease_s=lease_s, sampler="paper",
                                                   startup_trials=startup_trials), out, clock)
    return core, storage, clock


def free_endpoint() -> str:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{s.getsockname()[1]}"


def wait_for(predicate, timeout_s: float = 20.0, poll_s: float = 0.01, what: str = "condition"):
    """Poll until predicate() is truthy (events, not deadlines: time is never what is tested)."""
    import time

    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(poll_s)
    raise AssertionError(f"timed out waiting for {what}")
