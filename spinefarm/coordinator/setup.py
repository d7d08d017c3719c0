"""Wiring of one run: storage, sampler, study, scheduler and core, new or resumed."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

from spinefarm.coordinator.core import CoordinatorCore
from spinefarm.coordinator.ladder.checks import Checks
from spinefarm.coordinator.ladder.rungs import trial_scheduler
from spinefarm.coordinator.objectives import objective_fn, robust_objective
from spinefarm.coordinator.peers import PeerBook
from spinefarm.coordinator.samplers import DEFAULT_SAMPLER, make_sampler, sampler_class, sampler_from_dict
from spinefarm.coordinator.scheduler import Scheduler
from spinefarm.coordinator.study import Study
from spinefarm.protocol.engine_choice import EngineChoice
from spinefarm.protocol.environment import environment_record
from spinefarm.protocol.errors import ConfigError, check_range
from spinefarm.protocol.run import RunConfig
from spinefarm.protocol.settings import DEFAULT_ETA, AuditPolicy, JudgePolicy, Rung, RunSettings
from spinefarm.storage.base import BaseStorage
from spinefarm.storage.memory import InMemoryStorage
from spinefarm.storage.schema import RunMeta

Clock = Callable[[], float]  # seconds, monotonic

# The judge in the search's own engine re-simulates at this many times finer a step.
JUDGE_REFINE = 4


def software_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("spinefarm")
    except PackageNotFoundError:
        return "unknown"


@dataclass(frozen=True)
class SearchSettings:
    """How to search: budget, sampler and its settings (sigma, top_k: the paper's sampler), leases, the
    fidelity ladder (rungs: screening durations for successive halving, else one rung), the judge and
    the audit. The judge's rung is resolved against the run (see judge_rung)."""

    trials: int
    sampler: str = DEFAULT_SAMPLER
    sigma: float | None = None   # None: the sampler's default step (paper 0.005, cmaes sigma0 0.3)
    top_k: int = 1
    startup_trials: int | None = None   # None: half the budget is Monte Carlo
    lease_s: float = 60.0
    judge: JudgePolicy = field(default_factory=JudgePolicy)
    audit: AuditPolicy = field(default_factory=AuditPolicy)
    rungs: tuple[float, ...] | None = None   # multi-fidelity screening (successive halving over durations)
    eta: int = DEFAULT_ETA
    engine_choice: EngineChoice | None = None   # how --engine auto chose the tier (None: the engine was given)
    enqueued: tuple[tuple[float, ...], ...] = ()   # unit-cube parameter sets evaluated first (--enqueue)

    def __post_init__(self) -> None:
        check_range("trials", self.trials, 1)
        if len(self.enqueued) > self.trials:
            raise ConfigError("more enqueued parameter sets than trials", received=len(self.enqueued),
                              expected=f"at most --trials ({self.trials})")
        sampler_class(self.sampler)
        self._run_settings(self.judge)  # the ladder, eta and lease checked now, before any calibration

    def run_settings(self, config: RunConfig) -> RunSettings:
        n_params = len(config.space())
        lengths = sorted({len(u) for u in self.enqueued} - {n_params})
        if lengths:
            raise ConfigError("an enqueued parameter set does not fit the run's space", received=f"{lengths[0]} values",
                              expected=f"{n_params} values (the space of {config.morphology})")
        return self._run_settings(judge_rung(config, self.judge))

    def _run_settings(self, judge: JudgePolicy) -> RunSettings:
        ladder = (Rung(),) if self.rungs is None else tuple(Rung(duration_s=d) for d in self.rungs)
        return RunSettings(scheduler="plain" if self.rungs is None else "halving", ladder=ladder, eta=self.eta,
                           judge=judge, audit=self.audit, lease_s=self.lease_s, engine_choice=self.engine_choice,
                           enqueued=self.enqueued)


def judge_rung(config: RunConfig, judge: JudgePolicy) -> JudgePolicy:
    """The judge with its rung resolved: another engine at its own step, or the search's engine at a
    JUDGE_REFINE times finer step. A test objective has a judge only when one is named."""
    screen = config.trial_config.get("engine")
    rung = judge.rung
    if rung.engine == screen:
        rung = replace(rung, engine=None)
    if config.is_test_objective and rung.engine is None:
        return replace(judge, enabled=False)
    if rung.engine is None and rung.dt_s is None and not config.is_test_objective:
        from spinefarm.robot.trial_config import TrialConfig

        rung = replace(rung, dt_s=TrialConfig.from_dict(config.trial_config).step_s / JUDGE_REFINE)
    return replace(judge, rung=rung)


def make_meta(config: RunConfig, settings: SearchSettings) -> RunMeta:
    space = config.space()
    sampler = make_sampler(settings.sampler, len(space), config.seed, budget=settings.trials,
                           objective=config.objective, sigma=settings.sigma, top_k=settings.top_k,
                           startup_trials=settings.startup_trials,
                           start=settings.enqueued[0] if settings.enqueued else None)
    return RunMeta(run_id=config.run_id, morphology=config.morphology, controller=config.controller,
                   param_names=tuple(space.names),
                   param_lows=tuple(space.lows.tolist()), param_highs=tuple(space.highs.tolist()),
                   param_units=tuple(space.units),
                   objective=config.objective, seed=config.seed, trials_budget=settings.trials,
                   sampler=sampler.describe(), software_version=software_version(),
                   created_at_unix_s=time.time(), config_hash=config.config_hash(),
                   run=config.to_dict(), settings=settings.run_settings(config), environment=environment_record())


def build_core(storage: BaseStorage, clock: Clock = time.monotonic, trusted_peers: bool = False) -> CoordinatorCore:
    """A core over a storage that already holds its run (new or resumed). trusted_peers: access is
    controlled (--credentials), so a worker whose audits disagree is marked, not quarantined."""
    meta = storage.run_meta()
    config = RunConfig.from_dict(meta.run)
    space = config.space()
    settings = meta.settings
    sampler = sampler_from_dict(meta.sampler, len(space))
    objective = objective_fn(meta.objective)
    if config.robust:  # K episodes per parameter set, scored by a statistic over them
        objective = robust_objective(objective, config.robust["statistic"])
    study = Study(storage, sampler, space, meta.trials_budget, objective, meta.seed,
                  trial_scheduler(settings), enqueued=settings.enqueued)
    scheduler = Scheduler(clock, settings.lease_s)
    judged = settings.judge.enabled and (not config.is_test_objective or settings.judge.rung.engine is not None)
    checks = Checks(storage, settings, config.trial_config.get("engine"), meta.seed, judged)
    peers = PeerBook(quarantine=settings.audit.quarantine and not trusted_peers)
    return CoordinatorCore(study, scheduler, config, clock, checks=checks, peers=peers)


def new_run(config: RunConfig, settings: SearchSettings, out: str | Path | None,
            clock: Clock = time.monotonic, overwrite: bool = False,
            trusted_peers: bool = False) -> tuple[CoordinatorCore, BaseStorage]:
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
    return _core_or_close(storage, clock, trusted_peers), storage


def _core_or_close(storage: BaseStorage, clock: Clock, trusted_peers: bool = False) -> CoordinatorCore:
    try:
        return build_core(storage, clock, trusted_peers)
    except BaseException:
        storage.close()  # release the file and its lock: the error is the caller's to report
        raise


def resume_run(path: str | Path, clock: Clock = time.monotonic, trials_budget: int | None = None,
               trusted_peers: bool = False) -> tuple[CoordinatorCore, BaseStorage]:
    """Continue a stored run (optionally to a new budget): same numbering, same sampler state."""
    from spinefarm.storage.hdf5 import Hdf5Storage

    if not Path(path).is_file():
        raise ConfigError("cannot resume: run file does not exist", received=str(path),
                          expected="the .h5 file of an earlier run")
    from spinefarm.coordinator.study import trial_seed

    storage = Hdf5Storage.resume(path, trials_budget, seed_of=trial_seed)
    return _core_or_close(storage, clock, trusted_peers), storage
