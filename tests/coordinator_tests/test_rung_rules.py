"""The screen rungs' rules on storage alone, in-process (the searches of test_fidelity.py hold the same code
end to end): a rung's duration, when a plain and a halving run are done, a proposal's parent, a one-row rung."""

from __future__ import annotations

import math

import numpy as np

from spinefarm.coordinator.ladder.rungs import FirstRungView, HalvingTrialScheduler, PlainTrialScheduler
from spinefarm.protocol.settings import Rung, RunSettings
from tests.coordinator_tests.helpers import halving_ladder
from tests.coordinator_tests.test_fidelity import _result, _storage_with


def test_a_rung_without_a_duration_takes_the_runs_own_and_one_with_says_its_seconds():
    assert math.isnan(PlainTrialScheduler(RunSettings()).duration_s(0))
    assert PlainTrialScheduler(RunSettings(ladder=(Rung(duration_s=2.5),))).duration_s(0) == 2.5


def test_a_plain_run_is_done_at_its_budget_exactly():
    plain, st = PlainTrialScheduler(RunSettings()), _storage_with([0.3, 0.1, 0.2])
    assert [plain.done(st, 3, n) for n in (2, 3, 4)] == [False, True, True]


def test_a_halving_run_is_done_once_every_set_is_sampled_finished_and_nothing_is_left_to_promote():
    rungs = halving_ladder((1.0, 3.0), 3)
    st = _storage_with([0.1, 0.9, 0.5])
    assert not rungs.done(st, 4, 3)     # a set of the budget not sampled yet
    assert not rungs.done(st, 3, 3)     # all sampled and finished, but the best has not gone on
    st.add_trial(3, np.full(3, 0.5), np.zeros(3), "promoted", 1, 0, 1, 3.0)
    assert not rungs.done(st, 3, 3)     # its promotion sampled, not finished
    st.finish_trial(3, _result(3, 0.95), 0.95)
    assert rungs.done(st, 3, 4)
    assert not rungs.done(st, 3, 3)     # one fewer finished than rows


def test_a_proposals_parent_is_the_storage_row_of_its_view_row_and_none_stays_none():
    rungs = halving_ladder((1.0, 3.0), 3)
    st = _storage_with([0.1, 0.9, 0.5])
    st.add_trial(3, np.full(3, 0.5), np.zeros(3), "promoted", 1, 0, 1, 3.0)
    st.add_trial(4, np.full(3, 0.5), np.zeros(3), "monte_carlo", -1, 0, 0, 1.0)
    view = FirstRungView(st)
    assert [rungs.parent_id(view, p) for p in (0, 3, -1)] == [0, 4, -1]   # view row 3 is storage row 4
    assert PlainTrialScheduler(RunSettings()).parent_id(view, 3) == 3


def test_a_rung_of_one_row_sends_it_on_once_sampling_is_done_and_an_empty_one_sends_nothing():
    rungs = halving_ladder((1.0, 3.0), 3)
    assert rungs.promotion(_storage_with([]), True) is None
    one = _storage_with([0.4])
    assert rungs.promotion(one) is None and rungs.promotion(one, True) == 0


def test_once_a_rungs_quota_is_used_a_new_best_waits_for_the_end_to_go_on():
    rungs = halving_ladder((1.0, 3.0), 3)
    st = _storage_with([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])   # 6 // 3: two of rung 0 go on
    for expected in (5, 4):
        assert rungs.promotion(st) == expected
        st.add_trial(st.n_trials(), np.full(3, 0.5), np.zeros(3), "promoted", expected, 0, 1, 3.0)
    new = st.n_trials()
    st.add_trial(new, np.full(3, 0.5), np.zeros(3), "monte_carlo", -1, 0, 0, 1.0)
    st.finish_trial(new, _result(new, 0.9), 0.9)   # 7 rows: still two go on, and two have
    assert rungs.promotion(st) is None
    assert rungs.promotion(st, sampling_done=True) == new


def test_a_rung_whose_quota_is_used_leaves_the_rungs_below_free_to_promote():
    rungs = halving_ladder((1.0, 2.0, 3.0), 2)
    st = _storage_with([0.1, 0.2, 0.3, 0.4])          # rung 0: 4 // 2, two go on
    for source in (3, 2):
        tid = st.n_trials()
        st.add_trial(tid, np.full(3, 0.5), np.zeros(3), "promoted", source, 0, 1, 2.0)
        st.finish_trial(tid, _result(tid, 0.5 + tid / 10), 0.5 + tid / 10)
    st.add_trial(6, np.full(3, 0.5), np.zeros(3), "promoted", 5, 0, 2, 3.0)   # rung 1's one goes on: quota used
    for tid, obj in ((7, 0.8), (8, 0.7)):            # two more sets: rung 0 owes one more promotion (6 // 2 = 3)
        st.add_trial(tid, np.full(3, 0.5), np.zeros(3), "monte_carlo", -1, 0, 0, 1.0)
        st.finish_trial(tid, _result(tid, obj), obj)
    assert rungs.promotion(st) == 7


def test_at_the_end_only_a_rungs_best_goes_past_its_quota_and_once():
    rungs = halving_ladder((1.0, 3.0), 3)
    st = _storage_with([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    for source in (5, 4):
        st.add_trial(st.n_trials(), np.full(3, 0.5), np.zeros(3), "promoted", source, 0, 1, 3.0)
    for obj in (0.9, 0.8):                             # 8 rows: the quota (2) is used
        tid = st.n_trials()
        st.add_trial(tid, np.full(3, 0.5), np.zeros(3), "monte_carlo", -1, 0, 0, 1.0)
        st.finish_trial(tid, _result(tid, obj), obj)
    assert rungs.promotion(st, sampling_done=True) == 8     # the 0.9 set: the rung's best
    st.add_trial(st.n_trials(), np.full(3, 0.5), np.zeros(3), "promoted", 8, 0, 1, 3.0)
    assert rungs.promotion(st, sampling_done=True) is None  # not the 0.8 set too


def test_the_stored_scheduler_name_picks_its_class():
    from spinefarm.coordinator.ladder.rungs import trial_scheduler

    halving = RunSettings(scheduler="halving", ladder=(Rung(duration_s=1.0), Rung(duration_s=3.0)))
    assert type(trial_scheduler(halving)) is HalvingTrialScheduler
    assert type(trial_scheduler(RunSettings())) is PlainTrialScheduler


def test_a_promoted_row_walks_back_to_its_first_rung_row_through_every_parent():
    st = _storage_with([0.9, 0.1])
    st.add_trial(2, np.full(3, 0.5), np.zeros(3), "promoted", 0, 0, 1, 2.0)   # parent 0: the first row
    st.add_trial(3, np.full(3, 0.5), np.zeros(3), "promoted", 2, 0, 2, 3.0)
    st.add_trial(4, np.full(3, 0.5), np.zeros(3), "gaussian", 1, 0, 0, 1.0)   # a hill climber's child of row 1
    view = FirstRungView(st)
    assert [view.first_rung_row(t) for t in (3, 2, 1, 0, 4)] == [0, 0, 1, 0, 4]   # a sampler's parent is no rung


def test_a_samplers_best_sets_are_first_rung_rows_in_the_storages_order_each_once():
    st = _storage_with([0.1, 0.9, 0.5, 0.7, 0.6])
    st.add_trial(5, np.full(3, 0.5), np.zeros(3), "promoted", 2, 0, 1, 3.0)   # set 2 went on: it ranks first
    st.finish_trial(5, _result(5, 0.3), 0.3)
    st.add_trial(6, np.full(3, 0.5), np.zeros(3), "promoted", 4, 0, 1, 3.0)   # set 4 went on too
    st.finish_trial(6, _result(6, 0.2), 0.2)
    view = FirstRungView(st)   # view rows 0..4 are storage rows 0..4
    assert view.best_ids(0) == []
    assert view.best_ids(1) == [2]
    # the longer rung's two sets first, then the first rung by objective, each set once although its first-rung
    # row ranks again further down
    assert view.best_ids(4) == [2, 4, 1, 3]
    assert view.best_ids(5) == [2, 4, 1, 3, 0]   # the storage's best five repeat set 4: it asks for more
    assert view.best_ids(9) == [2, 4, 1, 3, 0]


def test_a_run_whose_quota_is_used_is_not_done_before_a_new_best_went_on():
    # every set sampled and every row finished, the rung's quota used: the new best (0.9) still goes on first
    rungs = halving_ladder((1.0, 3.0), 3)
    st = _storage_with([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    for source in (5, 4):
        tid = st.n_trials()
        st.add_trial(tid, np.full(3, 0.5), np.zeros(3), "promoted", source, 0, 1, 3.0)
        st.finish_trial(tid, _result(tid, 0.5 + source / 10), 0.5 + source / 10)
    st.add_trial(8, np.full(3, 0.5), np.zeros(3), "monte_carlo", -1, 0, 0, 1.0)
    st.finish_trial(8, _result(8, 0.9), 0.9)
    assert not rungs.done(st, 7, 9)


def test_a_sampler_never_sees_a_promoted_row_cut_from_its_first_rung():
    # a rung-1 row whose parent is lost (-1) has no first-rung row: it is left out, never an index past the view
    st = _storage_with([0.1, 0.2])
    st.add_trial(2, np.full(3, 0.5), np.zeros(3), "promoted", -1, 0, 1, 3.0)
    st.finish_trial(2, _result(2, 0.9), 0.9)
    assert FirstRungView(st).best_ids(3) == [1, 0]
