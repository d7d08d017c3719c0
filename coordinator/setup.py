"""Wiring of one run: storage, sampler, study, scheduler and core, new or resumed."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

from spinefarm.coordinator.core import CoordinatorCore
from spinefarm.coordinator.fidelity import Rungs
from spinefarm.coordinator.objectives import objective_fn
from spinefarm.coordinator.samplers import DEFAULT_SAMPLER, make_sampler, sampler_class, sampler_from_dict
from spinefarm.coordinator.scheduler import Scheduler
from spinefarm.coordinator.study import Study
from spinefarm.coordinator.verifier import Verifier, VerifyPolicy
from spinefarm.protocol.errors import ConfigError, check_range
from spinefarm.protocol.run import RunConfig
from spinefarm.storage.base import BaseStorage
from spinefarm.storage.memory import InMemoryStorage
from spinefarm.storage.schema import RunMeta


def software_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("spinefarm")
    except PackageNotFoundError:
        return "unknown"


@dataclass(frozen=True)
class SearchSettings:
    """How to search: budget, sampler and its settings (sigma, top_k: the paper's sampler), leases."""

    trials: int
    sampler: str = DEFAULT_SAMPLER
    sigma: float = 0.005
    top_k: int = 1
    startup_trials: int | None = None   # None: half the budget is Monte Carlo
    lease_s: float = 60.0
    verify: VerifyPolicy = field(default_factory=VerifyPolicy)
    rungs: Rungs | None = None   # multi-fidelity screening (successive halving over durations)

    def __post_init__(self) -> None:
        check_range("trials", self.trials, 1)
        check_range("lease_s", self.lease_s, 0.0, low_inclusive=False)
        sampler_class(self.sampler)


def make_meta(config: RunConfig, settings: SearchSettings) -> RunMeta:
    space = config.space()
    sampler = make_sampler(settings.sampler, len(space), config.seed, budget=settings.trials,
                           objective=config.objective, sigma=settings.sigma, top_k=settings.top_k,
                           startup_trials=settings.startup_trials)
    return RunMeta(run_id=config.run_id, morphology=config.morphology, controller=config.controller,
                   param_names=tuple(space.names),
                   param_lows=tuple(space.lows.tolist()), param_highs=tuple(space.highs.tolist()),
                   param_units=tuple(space.units),
                   objective=config.objective, seed=config.seed, trials_budget=settings.trials,
                   sampler=sampler.describe(), software_version=software_version(),
                   created_at_unix_s=time.time(), config_hash=config.config_hash(),
                   run=config.to_dict(), extra={"lease_s": settings.lease_s, "verify": settings.verify.to_dict(),
                                                "fidelity": None if settings.rungs is None else
                                                settings.rungs.to_dict()})


def build_core(storage: BaseStorage, clock=time.monotonic) -> CoordinatorCore:
    """A core over a storage that already holds its run (new or resumed)."""
    meta = storage.run_meta()
    config = RunConfig.from_dict(meta.run)
    space = config.space()
    sampler = sampler_from_dict(meta.sampler, len(space))
    study = Study(storage, sampler, space, meta.trials_budget, objective_fn(meta.objective), meta.seed,
                  Rungs.from_dict(meta.extra.get("fidelity")))
    scheduler = Scheduler(clock, float(meta.extra.get("lease_s", 60.0)))
    policy = VerifyPolicy.from_dict(meta.extra.get("verify"))
    verifier = Verifier(config, policy) if policy.enabled and Verifier.applies_to(config) else None
    return CoordinatorCore(study, scheduler, config, clock, verifier=verifier)


def new_run(config: RunConfig, settings: SearchSettings, out: str | Path | None,
            clock=time.monotonic, overwrite: bool = False) -> tuple[CoordinatorCore, BaseStorage]:
    """Create the run's storage (an HDF5 file, or memory when `out` is None) and its core.

    overwrite: replace an existing file, unless another coordinator holds it (storage.runlock)."""
    objective_fn(config.objective)  # fail before creating a file
    meta = make_meta(config, settings)
    if out is None:
        storage: BaseStorage = InMemoryStorage()
        storage.create_run(meta)
    else:
        from spinefarm.storage.hdf5 import Hdf5Storage

        storage = Hdf5Storage.create(out, meta, overwrite=overwrite)
    return _core_or_close(storage, clock), storage


def _core_or_close(storage: BaseStorage, clock) -> CoordinatorCore:
    try:
        return build_core(storage, clock)
    except BaseException:
        storage.close()  # release the file and its lock: the error is the caller's to report
        raise


def resume_run(path: str | Path, clock=time.monotonic,
               trials_budget: int | None = None) -> tuple[CoordinatorCore, BaseStorage]:
    """Continue a stored run (optionally to a new budget): same numbering, same sampler state."""
    from spinefarm.storage.hdf5 import Hdf5Storage

    if not Path(path).is_file():
        raise ConfigError("cannot resume: run file does not exist", received=str(path),
                          expected="the .h5 file of an earlier run")
    from spinefarm.coordinator.study import trial_seed

    storage = Hdf5Storage.resume(path, trials_budget, seed_of=trial_seed)
    return _core_or_close(storage, clock), storage
