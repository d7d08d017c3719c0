"""Samplers: unit cube, reproducible by trial number, hill climbing follows the best stored trial."""

from __future__ import annotations

import numpy as np
import pytest

from coordinator.samplers import GaussianHillClimbSampler, RandomSampler, sampler_from_dict
from protocol.errors import ConfigError
from storage.memory import InMemoryStorage
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


def test_failed_trials_are_never_centres(storage):
    from protocol.messages import TrialStatus

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
    with pytest.raises(ConfigError, match="unknown sampler"):
        sampler_from_dict({"kind": "Nope"}, 3)


@pytest.mark.parametrize("make", [
    lambda: RandomSampler(3, seed=21),
    lambda: GaussianHillClimbSampler(3, seed=21, startup_trials=5),
    lambda: GaussianHillClimbSampler(3, seed=21, sigma=0.2, top_k=3, startup_trials=0),
], ids=["random", "hill-climb", "hill-climb-top3"])
def test_sampler_contract(storage, make):
    """Every sampler: vectors in the unit cube, known phases, valid parents, reproducible from storage."""
    sampler = make()
    props = [record(storage, sampler, score=float(i % 7)) for i in range(40)]
    for i, p in enumerate(props):
        assert p.params_unit.shape == (3,) and p.params_unit.min() >= 0 and p.params_unit.max() <= 1
        assert p.phase in ("monte_carlo", "gaussian")
        assert (p.parent == -1) == (p.phase == "monte_carlo") and p.parent < i
    # A fresh sampler over the same storage (a restarted coordinator) proposes the same next trial.
    again = sampler_from_dict(sampler.describe(), 3)
    a, b = sampler.propose(40, storage), again.propose(40, storage)
    assert np.array_equal(a.params_unit, b.params_unit) and (a.phase, a.parent) == (b.phase, b.parent)
