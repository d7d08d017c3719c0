"""A run file with stored rows and the Ladder the core builds over it, in-process: the seam's rules driven
directly (test_ladder_seam_*.py). A sphere run screened in MuJoCo and judged in Bullet at 0.25 ms (the default
judge behind another engine, docs/distributed.md), so the judge's share never holds a check back."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from spinefarm.coordinator.ladder.checks import Checks
from spinefarm.coordinator.ladder.ladder import Ladder
from spinefarm.coordinator.peers import PeerBook
from spinefarm.coordinator.problem import build_run_config
from spinefarm.coordinator.scheduler import Lease, Scheduler
from spinefarm.coordinator.setup import SearchSettings, build_core, make_meta
from spinefarm.coordinator.study import trial_seed
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.settings import AuditPolicy, JudgePolicy, Rung
from spinefarm.protocol.submissions import Verdict
from spinefarm.storage.hdf5 import Hdf5Storage
from tests.coordinator_tests.helpers import FakeClock, queued_keys
from tests.storage_tests.conftest import result

SEED = 3
LEASE_S = 10.0
JUDGE = JudgePolicy(rung=Rung("bullet", 2.5e-4), share=1.0)
NO_AUDIT = AuditPolicy()
ENV_A = {"python": "3.11.9", "cpu": "x86_64 A"}
ENV_B = {"python": "3.11.9", "cpu": "aarch64 B"}


def outcome(tid: int, distance_m: float, worker: str, wall_time_s: float = 0.25) -> TrialResult:
    """A complete result of row `tid` carrying that row's seed."""
    r = result(tid, distance_m, seed=trial_seed(SEED, tid))
    return dataclasses.replace(r, worker_id=worker, wall_time_s=wall_time_s)


def store(storage: Hdf5Storage, distance_m: float, worker: str, duration_s: float = float("nan")) -> TrialResult:
    """Sample the next row and store its result (a NaN distance: leave it waiting)."""
    tid = storage.n_trials()
    storage.add_trial(tid, np.full(3, 0.25 + 0.1 * tid), np.zeros(3), "monte_carlo", -1, trial_seed(SEED, tid), 0,
                      duration_s)
    r = outcome(tid, distance_m, worker)
    if distance_m == distance_m:
        storage.finish_trial(tid, r, distance_m)
    return r


def arrive(ladder: Ladder, distance_m: float, worker: str) -> TrialResult:
    """A new row's result, stored and told to the ladder as the core does (study.tell, then after_trial)."""
    storage = ladder.study.storage
    tid = storage.n_trials()
    storage.add_trial(tid, np.full(3, 0.25 + 0.1 * tid), np.zeros(3), "monte_carlo", -1, trial_seed(SEED, tid))
    r = outcome(tid, distance_m, worker)
    assert ladder.study.tell(r)
    ladder.after_trial(r)
    return r


def lease(ladder: Ladder, key: int, worker: str) -> Lease:
    """Lease the queued `key` to `worker` (the keys queued before it keep their places)."""
    queued = queued_keys(ladder.leases)
    assert key in queued, f"{key} not queued: {queued}"
    for other in queued:
        ladder.leases.withdraw(other)
    ladder.leases.enqueue([key])
    [out] = ladder.leases.grant(worker, 1, lambda: None)
    ladder.leases.enqueue([k for k in queued if k != key])
    return out


def run_check(ladder: Ladder, key: int, worker: str, r: TrialResult) -> Verdict:
    """A worker takes the queued check `key` and sends its result back."""
    lease(ladder, key, worker)
    return ladder.settle_check(key, worker, r)


def run_file(path: Path, rows: tuple[tuple[float, str], ...], *, judge: JudgePolicy = JUDGE,
             audit: AuditPolicy = NO_AUDIT, trials: int = 20) -> Hdf5Storage:
    """A sphere run's file with `rows` (distance, worker; a NaN distance: sampled, still waiting)."""
    config = build_run_config("seam", "sphere:3", seed=SEED, trial_overrides={"engine": "mujoco"})
    settings = SearchSettings(trials=trials, sampler="random", lease_s=LEASE_S, judge=judge, audit=audit)
    storage = Hdf5Storage.create(path, make_meta(config, settings))
    for distance_m, worker in rows:
        store(storage, distance_m, worker)
    return storage


def ladder_of(storage: Hdf5Storage, clock: FakeClock | None = None, verify_identity: bool = False) -> Ladder:
    """The Ladder the coordinator's core builds over the file (a new one: everything pending rebuilt from it).
    verify_identity: workers' identities come from their sessions (the service's probe), not their ids."""
    clock = clock or FakeClock()
    core = build_core(storage, clock)
    if not verify_identity:
        return core.ladder
    settings = storage.run_meta().settings
    return Ladder(core.study, Scheduler(clock, LEASE_S), Checks(storage, settings, "mujoco", SEED, True),
                  PeerBook(quarantine=True, verify_identity=True), clock)
