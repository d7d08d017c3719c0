"""The judge, the audit and the drift rule as the docs state them (docs/stability.md, docs/accuracy.md,
coordinator.ladder.checks' contract), with distinct figures where a wrong rule would show: the judge's labels and its
tolerance, a disputed or disagreeing audit never best, three judged ratios in a row whose *median* leaves
[0.8, 1.2], the raised fidelity, and pending tasks issued again by a restarted coordinator (a real run file
reopened)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from spinefarm.coordinator.ladder.checks import Checks
from spinefarm.coordinator.ladder.keys import split_key
from spinefarm.protocol.settings import AuditPolicy, JudgePolicy, Rung, RunSettings, TaskFidelity
from spinefarm.protocol.states import AuditState, TrialStatus, Verification
from spinefarm.protocol.verdicts import judge_verdict
from spinefarm.storage.hdf5 import Hdf5Storage
from spinefarm.storage.hdf5_reader import Hdf5Reader
from spinefarm.storage.memory import InMemoryStorage
from tests.storage_tests.conftest import make_meta, result


def _stored(storage, distances_m) -> None:
    for tid, d in enumerate(distances_m):
        storage.add_trial(tid, np.full(3, 0.5), np.zeros(3), "monte_carlo", -1, tid)
        storage.finish_trial(tid, result(tid, d), d)


def _ok(distance_m, **extras):
    return dataclasses.replace(result(0, distance_m), extras=extras)


def test_the_judges_labels_and_its_tolerance():
    assert JudgePolicy().tolerance is None and JudgePolicy().drift == 0.2   # None: the robot's chaos floor
    same = (1.0, False, "bullet")
    assert judge_verdict(*same, _ok(1.04), 0.05) == (Verification.HOLDS, "")          # 4 % off the screen
    assert judge_verdict(*same, _ok(1.06), 0.05)[0] == Verification.MOVED             # 6 %
    assert judge_verdict(*same, _ok(0.96), 0.05)[0] == Verification.HOLDS
    assert judge_verdict(*same, _ok(1.0, perturbed_distance_m=1.2), 0.05)[0] == Verification.MOVED
    assert judge_verdict(*same, _ok(math.nan), 0.05)[0] == Verification.DIVERGED
    # another engine: its distance is reported whatever it is; only a failed run fails
    assert judge_verdict(1.0, True, "mujoco", _ok(2.5), 0.05) == (Verification.JUDGED, "")
    failed = dataclasses.replace(_ok(1.0), status=TrialStatus.FAILED, reason="diverged: nan")
    verdict, why = judge_verdict(1.0, True, "mujoco", failed, 0.05)
    assert verdict == Verification.DIVERGED and "diverged: nan" in why


@pytest.mark.parametrize("state", [AuditState.DISPUTED, AuditState.DISAGREES, AuditState.PENDING,
                                   AuditState.AGREES, AuditState.OVERRULED])
def test_a_disputed_or_disagreeing_audit_is_never_best(storage_kind, tmp_path, state):
    storage = InMemoryStorage() if storage_kind == "memory" else Hdf5Storage.create(tmp_path / "r.h5", make_meta())
    if storage_kind == "memory":
        storage.create_run(make_meta())
    _stored(storage, [3.0, 2.0, 1.0])
    storage.set_audit(0, state, 3.5, "w-2")
    barred = state in (AuditState.DISPUTED, AuditState.DISAGREES)
    assert storage.best_ids(2) == ([1, 2] if barred else [0, 1])
    storage.set_verification(1, Verification.DIVERGED, math.nan, "judge run failed: diverged")
    assert storage.best_ids(1) == ([2] if barred else [0])
    storage.close()
    if storage_kind == "hdf5":  # the API's reader of the file ranks as the writer does
        with Hdf5Reader(tmp_path / "r.h5") as reader:
            assert reader.best_ids(2) == ([2] if barred else [0, 2])


@pytest.fixture(params=["memory", "hdf5"])
def storage_kind(request):
    return request.param


def _judged(ratios, distances_m=None):
    s = InMemoryStorage()
    s.create_run(make_meta())
    distances_m = distances_m or [1.0] * len(ratios)
    _stored(s, distances_m)
    for tid, ratio in enumerate(ratios):  # ratio = screen / judge
        s.set_verification(tid, Verification.JUDGED, distances_m[tid] / ratio, "", ratio)
    return Checks(s, RunSettings(), "bullet", 7, judged=True)


@pytest.mark.parametrize(("ratios", "drifts"), [
    ((1.0, 1.05, 2.0), False),               # median 1.05 in [0.8, 1.2] (mean 1.35 is not)
    ((1.25, 1.3, 0.5), True),                # median 1.25 outside (mean 1.02 is inside)
    ((1.3, 1.0, 1.0, 1.3, 1.0, 0.7), False),  # never two of three in a row off the band
    ((1.0, 1.0, 0.7, 0.75, 1.0), True),      # 0.7, 0.75 in a row: median of (1.0, 0.7, 0.75) is 0.75
    ((1.19, 1.19, 1.19), False),             # inside, at 1 + 0.19
    ((1.21, 1.21), False),                   # two judged bests are not three
])
def test_drift_is_the_median_of_three_judged_ratios_in_a_row(ratios, drifts):
    assert (_judged(ratios).drift() is not None) == drifts


def test_bests_that_barely_move_say_nothing_of_drift():
    # ratios 1.5 of bests that move 5 cm (< 10 cm) in both runs: no drift; the same at 30 cm: drift
    assert _judged((1.5, 1.5, 1.5), [0.05, 0.05, 0.05]).drift() is None
    assert _judged((1.5, 1.5, 1.5), [0.3, 0.3, 0.3]).drift() is not None


def test_a_raised_fidelity_halves_the_step_or_moves_to_the_judges_engine():
    ladder = (Rung(dt_s=0.004, duration_s=2.0), Rung(duration_s=10.0))
    same = Checks(InMemoryStorage(), RunSettings(scheduler="halving", ladder=ladder,
                                                   judge=JudgePolicy(rung=Rung(dt_s=0.0005))), "mujoco", 7, True)
    assert same.trial_fidelity(0, raised=False).dt_s == 0.004
    assert same.trial_fidelity(0, raised=True).dt_s == 0.002      # half the rung's step
    assert same.trial_fidelity(1, raised=True).dt_s == 0.001      # half of 4 x the judge's step
    other = Checks(InMemoryStorage(), RunSettings(judge=JudgePolicy(rung=Rung("bullet", 0.0005))), "mujoco", 7,
                     True)
    assert other.trial_fidelity(0, raised=True) == TaskFidelity("trial", "bullet", 0.002, None)


def test_a_restarted_coordinator_issues_pending_judge_and_audit_tasks_again(tmp_path):
    path = tmp_path / "run.h5"
    s = Hdf5Storage.create(path, make_meta())
    _stored(s, [3.0, 2.0, 1.0, 0.5, 0.25])
    s.set_verification(0, Verification.PENDING)
    s.set_verification(1, Verification.HOLDS, 2.0, "", 1.0)
    s.set_verification(3, Verification.PENDING)
    s.set_audit(2, AuditState.PENDING)
    s.set_audit(4, AuditState.DISPUTED, 0.3, "w-2")
    s.close()
    again = Hdf5Storage.resume(path)
    checks = Checks(again, RunSettings(), "bullet", 7, judged=True)
    keys = checks.restart()
    assert sorted(split_key(k) for k in keys) == [("audit", 2), ("judge", 0), ("judge", 3), ("referee", 4)]
    assert checks.pending == set(keys)
    again.close()


def test_a_judge_in_the_runs_own_engine_named_outright_is_the_same_engine_and_halves_the_step():
    # the run screens in Bullet and the judge's rung names Bullet: not another engine, so the raised screen
    # stays in the run's engine at half of 4 x the judge's step (a run engine forgotten would move it to Bullet)
    named = Checks(InMemoryStorage(), RunSettings(judge=JudgePolicy(rung=Rung("bullet", 0.0005))), "bullet", 7, True)
    assert named.trial_fidelity(0, raised=True) == TaskFidelity("trial", None, 0.001, None)


def _audited(seed: int, fraction: float, n: int = 400) -> set[int]:
    s = InMemoryStorage()
    s.create_run(make_meta())
    _stored(s, [1.0 + 1e-3 * t for t in range(n)])   # each new row is the best: its audit is due anyway
    book = Checks(s, RunSettings(audit=AuditPolicy(fraction=fraction)), "bullet", seed, judged=True)
    return {t for t in range(n - 1) if book.audit_due(t) is not None}   # the last row, the best, left out


def test_the_audited_share_follows_the_fraction_and_the_draw_follows_the_runs_seed():
    seven, eight = _audited(7, 0.25), _audited(8, 0.25)
    # 399 draws of 0.25: mean 99.75, sd 8.6; 5 sd either way
    assert all(57 <= len(a) <= 143 for a in (seven, eight))
    assert seven == _audited(7, 0.25)       # a restarted coordinator draws the same rows
    assert seven != eight                   # another run's seed draws others
    assert len(_audited(7, 0.0)) == 0 and len(_audited(7, 1.0)) == 399


def test_the_drift_band_and_the_moving_threshold_include_their_ends():
    assert _judged((1.2, 1.2, 1.2)).drift() is None           # 1 + 0.2: inside
    assert _judged((0.8, 0.8, 0.8)).drift() is None           # 1 - 0.2: inside
    assert "[0.8, 1.2]" in _judged((1.5, 1.5, 1.5), [0.3] * 3).drift()
    # the screen moved exactly 0.1 m (the judge 0.1 / 1.5 m): it counts
    assert _judged((1.5, 1.5, 1.5), [0.1] * 3).drift() is not None
