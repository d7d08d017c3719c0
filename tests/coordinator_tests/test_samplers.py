"""Samplers: unit cube, reproducible by trial number, hill climbing follows the best stored trial."""

from __future__ import annotations

import re

import numpy as np
import pytest

from spinefarm.coordinator.samplers import (
    DEFAULT_SAMPLER,
    SAMPLERS,
    CmaEsSampler,
    GaussianHillClimbSampler,
    RandomSampler,
    make_sampler,
    sampler_from_dict,
)
from spinefarm.protocol.errors import ConfigError
from spinefarm.storage.memory import InMemoryStorage
from spinefarm.storage.schema import PHASE_PATTERN
from tests.storage_tests.conftest import make_meta, result


@pytest.fixture
def storage():
    s = InMemoryStorage()
    s.create_run(make_meta(n_params=3))
    return s


def record(storage, sampler, score=None):
    tid = storage.n_trials()
    p = sampler.propose(tid, storage)
    storage.add_trial(tid, p.params_unit, p.params_unit, p.phase, p.parent, tid)
    if score is not None:
        storage.finish_trial(tid, result(tid, score), score)
    return p


def test_random_sampler_is_uniform_in_the_cube_and_fixed_by_trial_number(storage):
    a, b = RandomSampler(3, seed=11), RandomSampler(3, seed=11)
    xs = np.array([a.propose(i, storage).params_unit for i in range(2000)])
    assert xs.min() >= 0 and xs.max() <= 1
    assert abs(xs.mean() - 0.5) < 0.02
    assert np.array_equal(b.propose(1234, storage).params_unit, xs[1234])
    assert not np.array_equal(RandomSampler(3, seed=12).propose(5, storage).params_unit, xs[5])


def test_hill_climb_starts_with_monte_carlo_then_steps_around_the_best(storage):
    s = GaussianHillClimbSampler(3, seed=1, sigma=0.005, startup_trials=4)
    for score in (1.0, 5.0, 2.0, 0.5):
        assert record(storage, s, score).phase == "monte_carlo"
    best = np.array(storage.trial(1).params_unit)
    steps = []
    for _ in range(300):
        p = record(storage, s)  # unfinished: the centre stays trial 1
        assert (p.phase, p.parent) == ("gaussian", 1)
        steps.append(p.params_unit - best)
    steps = np.array(steps)
    assert steps.std() == pytest.approx(0.005, rel=0.15)


def test_centre_moves_when_a_better_result_is_stored(storage):
    s = GaussianHillClimbSampler(3, seed=2, startup_trials=1)
    record(storage, s, 1.0)
    p = record(storage, s, 3.0)
    assert p.parent == 0
    assert record(storage, s).parent == 1


def test_top_k_draws_centres_among_the_k_best(storage):
    s = GaussianHillClimbSampler(3, seed=3, top_k=3, startup_trials=5)
    for score in (1.0, 9.0, 8.0, 7.0, 0.0):
        record(storage, s, score)
    parents = {record(storage, s).parent for _ in range(60)}
    assert parents == {1, 2, 3}


def test_samples_are_clipped_to_the_cube(storage):
    s = GaussianHillClimbSampler(3, seed=4, sigma=0.5, startup_trials=0)
    storage.add_trial(0, np.array([0.0, 1.0, 0.5]), np.zeros(3), "monte_carlo", -1, 0)
    storage.finish_trial(0, result(0, 1.0), 1.0)
    xs = np.array([s.propose(i, storage).params_unit for i in range(1, 200)])
    assert xs.min() == 0.0 and xs.max() == 1.0


def test_without_startup_trials_a_climb_steps_around_its_running_start(storage):
    """--enqueue a start and --startup-trials 0: while the start runs, the next trials step around it (a
    uniform sample would be a Monte Carlo trial the climb did not ask for)."""
    from spinefarm.protocol.states import TrialStatus

    s = GaussianHillClimbSampler(3, seed=6, sigma=0.01, startup_trials=0)
    assert s.propose(0, storage).phase == "monte_carlo"  # nothing stored: nothing to step around
    start = np.array([0.2, 0.4, 0.6])
    storage.add_trial(0, start, start, "enqueued", -1, 0)
    p = record(storage, s)
    assert (p.phase, p.parent) == ("gaussian", 0)
    assert np.abs(p.params_unit - start).max() < 0.1
    storage.finish_trial(0, result(0, 0.0, status=TrialStatus.FAILED, reason="diverged"), 0.0)
    assert record(storage, s).parent == 1  # a failed start is no centre: the next live trial is


def test_failed_trials_are_never_centres(storage):
    from spinefarm.protocol.states import TrialStatus

    s = GaussianHillClimbSampler(3, seed=5, startup_trials=1)
    record(storage, s, 1.0)
    tid = storage.n_trials()
    storage.add_trial(tid, np.zeros(3), np.zeros(3), "gaussian", 0, 1)
    storage.finish_trial(tid, result(tid, 99.0, status=TrialStatus.FAILED, reason="diverged"), 99.0)
    assert record(storage, s).parent == 0


def test_sampler_settings_round_trip_and_validate():
    s = GaussianHillClimbSampler(5, seed=9, sigma=0.01, top_k=2, startup_trials=7)
    again = sampler_from_dict(s.describe(), 5)
    assert again.describe() == s.describe()
    with pytest.raises(ConfigError, match="sigma"):
        GaussianHillClimbSampler(3, seed=0, sigma=0.0)
    GaussianHillClimbSampler(3, seed=0, sigma=1.0)  # a step the size of the unit cube is the most
    with pytest.raises(ConfigError, match="sigma"):
        GaussianHillClimbSampler(3, seed=0, sigma=1.5)
    with pytest.raises(ConfigError, match="unknown sampler"):
        sampler_from_dict({"kind": "Nope"}, 3)


def test_registry_names_every_sampler_and_rejects_unknown_names():
    assert {"paper", "cmaes", "tpe", "random"} <= set(SAMPLERS)
    assert DEFAULT_SAMPLER == "cmaes"  # bench/samplers.py (docs/samplers.md)
    for name, cls in SAMPLERS.items():
        assert cls.name == name
    with pytest.raises(ConfigError, match=r"unknown sampler.*annealing.*expected.*cmaes"):
        make_sampler("annealing", 3, 0, budget=10, objective="distance")
    old = {"kind": "GaussianHillClimbSampler", "seed": 2, "sigma": 0.01, "top_k": 1, "startup_trials": 3}
    assert sampler_from_dict(old, 3).name == "paper"  # files written before the registry


def contract_samplers():
    for name in SAMPLERS:
        yield pytest.param(lambda s, name=name: make_sampler(name, 3, s, budget=40, objective="distance"),
                           id=name)
    yield pytest.param(lambda s: GaussianHillClimbSampler(3, seed=s, sigma=0.2, top_k=3, startup_trials=0),
                       id="paper-top3")
    yield pytest.param(lambda s: make_sampler("tpe", 3, s, budget=40, objective="pareto"), id="tpe-pareto")
    yield pytest.param(lambda s: make_sampler("cmaes", 3, s, budget=40, objective="pareto"), id="cmaes-pareto")


def finish(storage, tid, score):
    storage.finish_trial(tid, result(tid, score), score)


@pytest.mark.parametrize("make", list(contract_samplers()))
def test_sampler_contract(make):
    """Every sampler: vectors in the unit cube, fixed by run seed and trial number, rebuilt from storage.

    Results arrive out of order (each trial finishes two asks later), as with several workers.
    """
    def run(seed, n=40):
        storage = InMemoryStorage()
        storage.create_run(make_meta(n_params=3))
        sampler = make(seed)
        props = []
        for tid in range(n):
            p = sampler.propose(tid, storage)
            storage.add_trial(tid, p.params_unit, p.params_unit, p.phase, p.parent, tid)
            props.append(p)
            if tid >= 2:
                finish(storage, tid - 2, float(-np.sum((props[tid - 2].params_unit - 0.3) ** 2)))
        return sampler, storage, props

    sampler, storage, props = run(21)
    for i, p in enumerate(props):
        assert p.params_unit.shape == (3,) and p.params_unit.min() >= 0 and p.params_unit.max() <= 1
        assert re.fullmatch(PHASE_PATTERN, p.phase.encode())
        assert -1 <= p.parent < i and (p.parent == -1) == (p.phase != "gaussian")
    assert len({tuple(p.params_unit) for p in props}) == len(props)
    # same run seed: the same proposals; another seed: others
    again = run(21)[2]
    assert all(np.array_equal(a.params_unit, b.params_unit) for a, b in zip(props, again, strict=True))
    other = run(22)[2]
    assert not np.array_equal(props[-1].params_unit, other[-1].params_unit)
    # A fresh sampler over the same storage (a restarted coordinator) proposes the same next trial,
    # also after a result with a lower id arrives late.
    for _ in range(2):
        fresh = sampler_from_dict(sampler.describe(), 3)
        a, b = sampler.propose(40, storage), fresh.propose(40, storage)
        assert np.array_equal(a.params_unit, b.params_unit) and (a.phase, a.parent) == (b.phase, b.parent)
        finish(storage, 38, 0.5)


@pytest.mark.parametrize("name", ["cmaes", "tpe"])
def test_model_based_samplers_improve_on_random_search(name):
    """On a smooth bowl in 4 dimensions, 150 trials get closer to the top than 150 uniform draws."""
    def best_after(sampler_name, seed, n=150):
        storage = InMemoryStorage()
        storage.create_run(make_meta(n_params=4))
        sampler = make_sampler(sampler_name, 4, seed, budget=n, objective="distance")
        best = -np.inf
        for tid in range(n):
            p = sampler.propose(tid, storage)
            storage.add_trial(tid, p.params_unit, p.params_unit, p.phase, p.parent, tid)
            score = float(-np.sum((p.params_unit - 0.3) ** 2))
            finish(storage, tid, score)
            best = max(best, score)
        return best

    model = np.median([best_after(name, s) for s in range(3)])
    random = np.median([best_after("random", s) for s in range(3)])
    assert model > random and model > -1e-3


def test_cmaes_restarts_with_a_larger_population_when_it_converges():
    storage = InMemoryStorage()
    storage.create_run(make_meta(n_params=2))
    sampler = CmaEsSampler(2, seed=5)
    sizes = []
    for tid in range(1500):
        p = sampler.propose(tid, storage)
        storage.add_trial(tid, p.params_unit, p.params_unit, p.phase, p.parent, tid)
        finish(storage, tid, float(-np.sum((p.params_unit - 0.7) ** 2)))
        sizes.append(sampler._cma.population_size)
    assert sampler.restarts >= 1 and max(sizes) == 2 * sampler.population_size * 2 ** (sampler.restarts - 1)
    rebuilt = sampler_from_dict(sampler.describe(), 2)
    rebuilt.propose(1500, storage)
    assert rebuilt.restarts == sampler.restarts


def test_cmaes_needs_two_parameters():
    with pytest.raises(ConfigError, match="cmaes needs at least 2 parameters; received 1"):
        make_sampler("cmaes", 1, 0, budget=10, objective="distance")


def test_cmaes_starts_from_the_enqueued_set_with_the_given_sigma(tmp_path):
    """--sampler cmaes --enqueue GAIT --sigma S: the first generation is drawn around the enqueued set at step S
    (not around the cube's centre), and a resumed run rebuilds that start from the run file."""
    from spinefarm.coordinator.problem import build_run_config
    from spinefarm.coordinator.setup import SearchSettings, new_run, resume_run

    start = (0.1, 0.85, 0.3)
    config = build_run_config("r", "sphere:3", seed=4)
    settings = SearchSettings(trials=30, sampler="cmaes", sigma=0.01, enqueued=(start,))
    core, storage = new_run(config, settings, tmp_path / "run.h5")
    assert core.study.sampler.mean0 == start
    for tid in range(6):
        assert core.study.ask() == tid
    rows = np.array([storage.trial(t).params_unit for t in range(6)])
    assert storage.trial(0).phase == "enqueued" and np.allclose(rows[0], start)
    assert np.abs(rows[1:] - start).max() < 0.06  # 6 sigma; around the centre 0.5 they would be ~0.4 away
    expected = core.study.sampler.propose(6, storage)
    storage.close()
    core2, storage2 = resume_run(tmp_path / "run.h5")
    assert core2.study.sampler.mean0 == start
    assert np.array_equal(core2.study.sampler.propose(6, storage2).params_unit, expected.params_unit)
    storage2.close()
    plain = make_sampler("cmaes", 3, 4, budget=30, objective="distance")
    assert (plain.mean0, plain.sigma0) == (None, 0.3)  # no start, no --sigma: the defaults


def test_cmaes_rejects_a_start_outside_the_cube_and_reads_files_from_before_starts():
    with pytest.raises(ConfigError, match=r"outside the unit cube; received \[1.5\]"):
        make_sampler("cmaes", 3, 0, budget=10, objective="distance", start=(0.2, 1.5, 0.3))
    with pytest.raises(ConfigError, match="does not fit the run's space; received '2 values'"):
        make_sampler("cmaes", 3, 0, budget=10, objective="distance", start=(0.2, 0.3))
    older = {"name": "cmaes", "kind": "CmaEsSampler", "seed": 3, "sigma0": 0.3, "population_size": 7,
             "population_growth": 2.0}  # a run file written before cmaes had a start point
    assert sampler_from_dict(older, 3).mean0 is None
    with pytest.raises(ConfigError, match=r"--sigma does not apply to the tpe sampler; received 0.1"):
        make_sampler("tpe", 3, 0, budget=10, objective="distance", sigma=0.1)


@pytest.mark.parametrize("name", ["cmaes", "tpe"])
def test_the_sampler_is_stored_with_the_run_and_rebuilt_on_resume(tmp_path, name):
    from spinefarm.coordinator.problem import build_run_config
    from spinefarm.coordinator.setup import SearchSettings, new_run, resume_run

    config = build_run_config("r", "sphere:3", seed=8)
    core, storage = new_run(config, SearchSettings(trials=30, sampler=name), tmp_path / "run.h5")
    for tid in range(12):
        assert core.study.ask() == tid
        if tid % 3:  # some results missing, as after a crash
            finish(storage, tid, float(-tid % 5))
    expected = core.study.sampler.propose(12, storage)
    storage.close()
    core2, storage2 = resume_run(tmp_path / "run.h5")
    assert type(core2.study.sampler) is SAMPLERS[name]
    got = core2.study.sampler.propose(12, storage2)
    assert np.array_equal(expected.params_unit, got.params_unit)
    storage2.close()


def test_the_samplers_defaults_are_the_documented_ones(storage):
    """docs/samplers.md: the paper's sampler steps with sigma = 0.005 (the paper's figure) after Monte Carlo
    over half the budget; CMA-ES starts at sigma0 = 0.3; TPE has 10 random start-up trials; the default sampler
    is CMA-ES. Read from what the samplers draw, not from their attributes."""
    paper = make_sampler("paper", 3, 5, budget=9, objective="distance")
    phases = [record(storage, paper, score=float(i + 1)).phase for i in range(4)]
    assert phases == ["monte_carlo"] * 4  # half of 9, rounded down
    centre = np.array(storage.trial(3).params_unit)  # the best of the four
    steps = np.array([record(storage, paper).params_unit - centre for _ in range(400)])
    assert record(storage, paper).phase == "gaussian"
    assert 0.0045 < steps.std() < 0.0055, steps.std()
    assert DEFAULT_SAMPLER == "cmaes"
    cma = make_sampler("cmaes", 3, 5, budget=8, objective="distance")
    assert cma.describe()["sigma0"] == 0.3
    tpe = make_sampler("tpe", 3, 5, budget=100, objective="distance")
    assert tpe.describe()["startup_trials"] == 10


def test_a_stored_sampler_is_found_by_its_name_or_by_an_older_files_kind():
    named = {"name": "paper", "seed": 1, "sigma": 0.01, "top_k": 1, "startup_trials": 0}  # no kind
    again = sampler_from_dict(named, 3)
    assert isinstance(again, GaussianHillClimbSampler) and again.sigma == 0.01
    older = {"kind": "RandomSampler", "seed": 4}  # written before samplers had names
    assert isinstance(sampler_from_dict(older, 3), RandomSampler)
