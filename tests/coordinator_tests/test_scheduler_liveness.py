"""A worker counts as live for lease_s after it last spoke (scheduler's docstring): measured from the time it
spoke, on a clock that does not start at zero, so the silence is `now - last_contact_s` and nothing else."""

from __future__ import annotations

import itertools

from spinefarm.coordinator.scheduler import Scheduler
from tests.coordinator_tests.helpers import FakeClock


def test_a_retried_trial_waits_for_a_live_worker_until_it_has_been_silent_a_lease():
    clock = FakeClock(1000.0)
    s = Scheduler(clock, lease_s=5.0, start_grace_s=0.0)
    counter = itertools.count()
    ids = lambda: (n if (n := next(counter)) < 1 else None)  # noqa: E731 - one trial in all
    s.contact("w1")                     # w1 speaks at t = 1000 s
    assert [ls.trial_id for ls in s.grant("w0", 1, ids)] == [0]
    s.retry(0, "timeout: no result within its 1 s wall-clock limit")
    for t in (1001.0, 1003.0, 1004.9):  # w1 silent 1, 3 and 4.9 s: still live, so w0 must not take it back
        clock.t = t
        assert s.grant("w0", 1, ids) == [], t
    clock.t = 1005.1                    # silent 5.1 s > lease_s: no longer live, w0 is the only one left
    assert [ls.trial_id for ls in s.grant("w0", 1, ids)] == [0]
    assert s.failed_on(0) == ["w0"]


def test_a_worker_is_speaking_while_its_token_is_up_and_it_spoke_within_a_lease():
    """`speaking` (whether a promotion may wait for the worker that ran its rung): never for a worker never heard,
    for one heard 4.9 s ago on a 5 s lease, not 5.1 s after, not once its liveliness token went, on a clock far
    from zero so a sum in place of the difference shows."""
    clock = FakeClock(1000.0)
    s = Scheduler(clock, lease_s=5.0, start_grace_s=0.0)
    assert not s.speaking("w-never")
    s.contact("w1")
    s.contact("w2")
    clock.t = 1004.9
    assert s.speaking("w1") and s.speaking("w2")
    s.worker_lost("w2")
    assert s.speaking("w1") and not s.speaking("w2")
    clock.t = 1005.1
    assert not s.speaking("w1")
    s.contact("w1")
    assert s.speaking("w1")
