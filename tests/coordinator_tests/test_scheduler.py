"""Leases with deadlines on an injected clock: expiry and worker loss re-issue, stale leases refused."""

from __future__ import annotations

import dataclasses
import itertools

import pytest

from spinefarm.coordinator.scheduler import Scheduler
from spinefarm.protocol.errors import ConfigError
from tests.coordinator_tests.helpers import FakeClock, queued_keys


def new_ids(limit: int = 1000):
    counter = itertools.count()
    return lambda: (n if (n := next(counter)) < limit else None)


def test_grant_leases_new_trials_with_staggered_deadlines():
    clock = FakeClock(0.0)
    s = Scheduler(clock, lease_s=5.0)
    leases = s.grant("w1", 3, new_ids())
    assert [ls.trial_id for ls in leases] == [0, 1, 2]
    assert [ls.deadline_s for ls in leases] == [5.0, 10.0, 15.0]
    assert len({ls.lease_id for ls in leases}) == 3
    assert s.n_leased == 3 and s.workers["w1"].leases == {0, 1, 2}


def test_grant_stops_when_no_trial_is_left():
    s = Scheduler(FakeClock(), lease_s=5.0)
    assert len(s.grant("w1", 10, new_ids(limit=4))) == 4
    assert s.grant("w2", 10, new_ids(limit=0)) == []


def test_expired_lease_is_reissued_with_a_new_lease_id():
    clock = FakeClock(0.0)
    s = Scheduler(clock, lease_s=5.0)
    ids = new_ids()
    first = s.grant("w1", 2, ids)
    clock.advance(5.0)
    assert s.expire() == [0]
    assert s.n_queued == 1 and s.lease_of(0) is None
    again = s.grant("w2", 1, ids)
    assert again[0].trial_id == 0 and again[0].lease_id != first[0].lease_id
    assert not s.is_current(0, first[0].lease_id, "w1")
    assert s.is_current(0, again[0].lease_id, "w2")
    clock.advance(4.9)
    assert s.expire() == []
    clock.advance(0.1)  # trial 1's first deadline and trial 0's second one
    assert s.expire() == [0, 1]


def test_release_forgets_the_lease_so_it_never_expires():
    clock = FakeClock(0.0)
    s = Scheduler(clock, lease_s=1.0)
    (lease,) = s.grant("w1", 1, new_ids())
    s.release(lease.trial_id)
    clock.advance(100.0)
    assert s.expire() == [] and s.n_queued == 0


def test_lost_worker_leases_are_reissued_at_once_before_new_trials():
    clock = FakeClock(0.0)
    s = Scheduler(clock, lease_s=60.0)
    ids = new_ids()
    s.grant("w1", 3, ids)
    s.grant("w2", 1, ids)
    assert s.worker_lost("w1") == [0, 1, 2]
    assert not s.workers["w1"].alive and s.workers["w2"].alive
    assert [ls.trial_id for ls in s.grant("w2", 4, ids)] == [0, 1, 2, 4]
    assert s.worker_lost("never-seen") == []
    assert s.reissued == 3


def test_contact_tracks_last_contact_on_the_clock():
    clock = FakeClock(10.0)
    s = Scheduler(clock)
    s.contact("w1")
    clock.advance(2.5)
    s.contact("w1")
    assert s.workers["w1"].last_contact_s == 12.5


def test_lease_must_be_positive():
    with pytest.raises(ConfigError, match="lease_s"):
        Scheduler(FakeClock(), lease_s=0.0)


def _fail(s: Scheduler, worker_id: str, trial_id: int = 0) -> None:
    """The lease holder gives the trial back: it timed out there."""
    assert s.lease_of(trial_id).worker_id == worker_id
    s.retry(trial_id, "timeout: no result within its 1 s wall-clock limit")


def test_a_timed_out_trial_goes_to_a_worker_that_has_not_failed_it():
    s = Scheduler(FakeClock(0.0), lease_s=5.0)
    ids = new_ids(limit=1)
    for w in ("w0", "w1", "w2"):
        s.contact(w)
    assert [ls.trial_id for ls in s.grant("w0", 1, ids)] == [0]
    _fail(s, "w0")
    assert s.grant("w0", 1, ids) == []  # w1 and w2 are live and have not failed it
    assert [ls.trial_id for ls in s.grant("w1", 1, ids)] == [0]
    _fail(s, "w1")
    assert s.grant("w0", 1, ids) == [] and s.grant("w1", 1, ids) == []
    assert [ls.trial_id for ls in s.grant("w2", 1, ids)] == [0]
    _fail(s, "w2")
    assert s.given_up == [(0, "timeout: no result within its 1 s wall-clock limit (3 attempts) on 3 workers: "
                              "w0, w1, w2")]
    assert s.n_queued == 0 and s.failed_on(0) == []


def test_with_one_worker_a_timed_out_trial_comes_back_to_it_and_is_still_capped(caplog):
    s = Scheduler(FakeClock(0.0), lease_s=5.0, start_grace_s=0.0)
    ids = new_ids(limit=3)
    s.grant("w0", 1, ids)
    for _ in range(2):
        _fail(s, "w0")
        assert [ls.trial_id for ls in s.grant("w0", 1, ids)] == [0]  # before new trials: nobody else can run it
    _fail(s, "w0")
    assert s.given_up == [(0, "timeout: no result within its 1 s wall-clock limit (3 attempts) on 1 worker: w0")]
    said = [r.getMessage() for r in caplog.records]
    assert said == ["trial 0 goes back to worker w0, which it timed out or crashed on: no other live worker may "
                    "run it (live: w0)"] * 2


def test_a_worker_that_is_gone_or_silent_does_not_hold_a_retried_trial_back():
    clock = FakeClock(0.0)
    s = Scheduler(clock, lease_s=5.0)
    ids = new_ids(limit=1)
    s.contact("w1")
    s.contact("w2")
    s.grant("w0", 1, ids)
    _fail(s, "w0")
    s.worker_lost("w1")            # its token vanished
    clock.advance(10.0)            # w2 has not spoken for longer than a lease (and the start grace is over)
    s.contact("w0")
    assert [ls.trial_id for ls in s.grant("w0", 1, ids)] == [0]
    assert s.failed_on(0) == ["w0"]


def test_a_retried_trial_skips_a_worker_that_may_not_run_it():
    s = Scheduler(FakeClock(0.0), lease_s=5.0, start_grace_s=0.0)
    ids = new_ids(limit=1)
    s.contact("w1")  # live, but it does not run this trial's engine
    s.grant("w0", 1, ids)
    _fail(s, "w0")
    only_w0 = lambda key, wid: wid == "w0"  # noqa: E731
    assert [ls.trial_id for ls in s.grant("w0", 1, ids, only_w0)] == [0]


def test_a_lost_lease_prefers_another_worker_and_comes_back_when_nothing_else_is_left():
    clock = FakeClock(0.0)
    s = Scheduler(clock, lease_s=5.0)
    ids = new_ids(limit=2)
    s.contact("w1")
    s.grant("w0", 1, ids)
    clock.advance(5.0)
    assert s.expire() == [0]
    s.contact("w1")
    assert [ls.trial_id for ls in s.grant("w0", 1, ids)] == [1]  # a new trial first; trial 0 waits for w1
    assert [ls.trial_id for ls in s.grant("w0", 1, ids)] == [0]  # no new trial left: it may run it again
    assert s.failed_on(0) == ["w0"]


def test_given_up_after_lost_leases_names_the_workers():
    s = Scheduler(FakeClock(0.0), lease_s=5.0, max_attempts=2)
    ids = new_ids(limit=1)
    s.grant("w0", 1, ids)
    s.worker_lost("w0")
    s.grant("w1", 1, ids)
    s.worker_lost("w1")
    assert s.given_up == [(0, "lost its worker 2 times (last: worker w1 vanished) on 2 workers: w0, w1")]


def test_just_after_a_start_a_timed_out_trial_waits_for_other_workers_to_reconnect():
    clock = FakeClock(0.0)
    s = Scheduler(clock, lease_s=5.0, start_grace_s=10.0)
    ids = new_ids(limit=2)
    s.grant("w0", 1, ids)
    _fail(s, "w0")
    assert [ls.trial_id for ls in s.grant("w0", 1, ids)] == [1]  # the only worker known so far
    assert s.grant("w0", 1, ids) == []
    s.release(1)
    s.contact("w1")  # reconnected
    assert [ls.trial_id for ls in s.grant("w1", 1, ids)] == [0]
    _fail(s, "w1")
    s.worker_lost("w1")
    clock.advance(10.0)  # grace over, nobody else: back to a worker that failed it
    assert [ls.trial_id for ls in s.grant("w0", 1, ids)] == [0]


def test_a_measured_trial_time_staggers_the_leases_of_a_batch():
    """docs/distributed.md: lease_s for the first trial of a batch, plus the expected trial time, 4x the
    measured wall time (a running mean) and at most lease_s, for each one after it."""
    clock = FakeClock(0.0)
    s, ids = Scheduler(clock, lease_s=60.0), new_ids()
    s.observe_trial(0.5)  # first measurement: 4 x 0.5 s = 2 s per trial ahead in the batch
    assert [ls.deadline_s for ls in s.grant("w1", 3, ids)] == [60.0, 62.0, 64.0]
    s.observe_trial(2.5)  # slower trials: 4 x 2.5 = 10 s, mixed into the mean: between 2 s and 10 s
    clock.t = 10.0
    later = [ls.deadline_s - 70.0 for ls in s.grant("w2", 3, ids)]
    assert later[0] == 0.0 and later[1] == pytest.approx(0.8 * 2.0 + 0.2 * 10.0) and later[2] == pytest.approx(7.2)
    for not_a_time in (0.0, -1.0, float("nan")):  # not a measurement: the stagger stays
        s.observe_trial(not_a_time)
    assert s.expected_trial_s == pytest.approx(3.6)
    capped = Scheduler(FakeClock(0.0), lease_s=5.0)
    capped.observe_trial(30.0)  # 4 x 30 s is capped at lease_s
    capped.observe_trial(float("nan"))  # not a measurement
    assert [ls.deadline_s for ls in capped.grant("w1", 3, new_ids())] == [5.0, 10.0, 15.0]


def test_the_documented_bounds_of_a_grant():
    """docs/distributed.md: at most 64 trials per request and per worker at a time; leases of 60 s unless
    told; a scheduler may grant one trial at a time and give a trial up after one lost lease."""
    clock = FakeClock(0.0)
    s, ids = Scheduler(clock), new_ids()
    first = s.grant("w1", 1000, ids)
    assert len(first) == 64 and first[0].deadline_s == 60.0
    assert s.grant("w1", 1000, ids) == []  # it holds 64 already
    s.release(first[0].trial_id)
    assert len(s.grant("w1", 1000, ids)) == 1
    one = Scheduler(clock, lease_s=5.0, max_grant=1, max_attempts=1)
    assert len(one.grant("w2", 10, new_ids())) == 1
    with pytest.raises(dataclasses.FrozenInstanceError):
        first[0].deadline_s = 1e9  # a lease is not stretched in place


def test_a_new_trial_a_worker_may_not_run_is_queued_for_another():
    s, ids = Scheduler(FakeClock(0.0), lease_s=5.0), new_ids()
    not_one = lambda key, worker: not (key == 1 and worker == "w1")  # noqa: E731  e.g. an engine w1 lacks
    assert [ls.trial_id for ls in s.grant("w1", 3, ids, not_one)] == [0]  # the batch ends at trial 1
    assert s.queued(1) and [ls.trial_id for ls in s.grant("w2", 1, ids, not_one)] == [1]
    assert [ls.trial_id for ls in s.grant("w1", 2, ids, not_one)] == [2, 3]


def test_tasks_go_first_withdrawn_keys_are_forgotten_and_a_late_result_is_known_from_a_forged_one():
    clock = FakeClock(0.0)
    s, ids = Scheduler(clock, lease_s=5.0), new_ids()
    held = s.grant("w1", 3, ids)
    s.enqueue([10, 11])
    s.push_front(-4)  # a judge task: before anything queued
    s.push_front(-4)  # once
    s.push_front(held[0].trial_id)  # leased already: not queued again
    assert queued_keys(s) == [-4, 10, 11]
    s.withdraw(10)
    s.withdraw(held[1].trial_id)  # leased: dropped, its worker no longer holds it
    assert queued_keys(s) == [-4, 11] and s.lease_of(held[1].trial_id) is None
    assert s.workers["w1"].leases == {held[0].trial_id, held[2].trial_id}
    # the issue is remembered: a late result of that lease is stale, one quoting a lease never given is forged
    assert s.was_issued(held[1].trial_id, held[1].lease_id, "w1")
    assert not s.was_issued(held[1].trial_id, held[1].lease_id, "w2")
    assert not s.was_issued(held[1].trial_id, held[1].lease_id + 1, "w1")
    # a worker's keys taken back go first, in key order, and it holds nothing
    assert s.take_back("w1") == [held[0].trial_id, held[2].trial_id]
    assert queued_keys(s) == [held[0].trial_id, held[2].trial_id, -4, 11] and s.workers["w1"].leases == set()
    assert s.take_back("nobody") == []


def test_a_worker_asking_three_times_without_its_grant_loses_it_to_another_worker():
    """The rule as documented (scheduler.MAX_UNREPORTED = 3): the first two asks without a granted trial take it
    back and issue it first again (to the asker); the third bars it from that worker while another live one may run
    it; from then on the asker is granted one new trial per lease_s, lost as a silent worker's lease is (an attempt
    counted) when it asks again without it."""
    clock = FakeClock(0.0)
    s, ids = Scheduler(clock, lease_s=5.0, start_grace_s=0.0), new_ids()
    s.contact("w2")
    assert [ls.trial_id for ls in s.grant("w1", 2, ids)] == [0, 1]
    for _ in range(2):   # a lost reply: the same trials go back to the same asker
        assert s.take_back_unreported("w1") == ([0, 1], False)
        assert [ls.trial_id for ls in s.grant("w1", 2, ids)] == [0, 1]
    assert s.take_back_unreported("w1") == ([0, 1], True)
    assert [ls.trial_id for ls in s.grant("w1", 2, ids)] == [2]  # a new one, one at a time
    assert [ls.trial_id for ls in s.grant("w2", 4, ids)] == [0, 1, 3, 4]
    assert s.take_back_unreported("w1") == ([], False)  # it keeps failing: trial 2 lost as a silent worker's
    assert s.workers["w1"].leases == set() and queued_keys(s) == [2] and s.failed_on(2) == ["w1"]
    assert s.grant("w1", 2, ids) == []   # nothing until lease_s after its last trial
    assert [ls.trial_id for ls in s.grant("w2", 1, ids)] == [2]
    for tid in (0, 1, 2, 3, 4):
        s.release(tid)   # w2 ran them
    clock.advance(5.0)
    assert [ls.trial_id for ls in s.grant("w1", 2, ids)] == [5]


def test_a_worker_that_never_runs_its_grants_alone_ends_each_trial_by_the_lease_rules():
    """Alone, it gets its lost trials back; each is stored as failed after max_attempts (3) lost leases."""
    clock = FakeClock(0.0)
    s, ids = Scheduler(clock, lease_s=5.0, start_grace_s=0.0), new_ids()
    for _ in range(3):
        s.grant("w1", 1, ids)
        s.take_back_unreported("w1")
    for _ in range(3):
        assert [ls.trial_id for ls in s.grant("w1", 1, ids)] == [0]
        s.take_back_unreported("w1")
        clock.advance(5.0)
    assert [tid for tid, _ in s.given_up] == [0] and "lost its worker 3 times" in s.given_up[0][1]


def test_a_worker_that_returns_a_result_again_gets_its_grants_again():
    clock = FakeClock(0.0)
    s, ids = Scheduler(clock, lease_s=5.0, start_grace_s=0.0, max_unreported=2), new_ids()
    s.contact("w2")
    s.grant("w1", 1, ids)
    s.take_back_unreported("w1")
    s.grant("w1", 1, ids)
    assert s.take_back_unreported("w1") == ([0], True)
    (lease,) = s.grant("w1", 3, ids)
    s.release(lease.trial_id)   # it ran one after all: back to full batches and lost grants re-issued to it
    assert len(s.grant("w1", 3, ids)) == 3 and s.take_back_unreported("w1")[1] is False
