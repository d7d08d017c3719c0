"""A promotion goes first to the worker that ran the set's last rung (it may go on from that rung's kept end,
worker.trial.continued), waits for that worker while new sets are still sampled and it is live, and goes to
whoever asks once sampling is done or that worker is gone; --no-continue restores the plain order and has every
trial simulated from the start. The coordinator core over real messages, successive halving on the test objective."""

from __future__ import annotations

import dataclasses

import numpy as np

from spinefarm.coordinator.ladder.rungs import Asker
from spinefarm.coordinator.problem import build_run_config
from spinefarm.coordinator.setup import SearchSettings, new_run
from spinefarm.protocol.settings import AuditPolicy
from tests.coordinator_tests.helpers import FakeClock, halving_ladder
from tests.coordinator_tests.test_core import ask, res, submit
from tests.coordinator_tests.test_fidelity import _result, _storage_with

LEASE_S = 10.0


def _core(trials: int = 8):
    clock = FakeClock()
    config = build_run_config("promote", "sphere:3", seed=5)
    core, storage = new_run(config, SearchSettings(trials=trials, lease_s=LEASE_S, sampler="random",
                                                   rungs=(1.0, 3.0), eta=2), None, clock)
    return core, storage, clock


def _screen(core, distances: dict[str, tuple[float, float]]) -> None:
    """Each worker takes two first-rung sets and returns them with the given distances."""
    for worker, values in distances.items():
        grant = ask(core, worker, 2)
        submit(core, [(a.lease_id, res(a, worker, d)) for a, d in zip(grant.assignments, values, strict=True)], worker)


def _one(core, worker: str):
    """One task for `worker`, its result returned at once (a worker asking while it holds a lease gets it again)."""
    (a,) = ask(core, worker, 1).assignments
    submit(core, [(a.lease_id, res(a, worker, 0.5))], worker)
    return a


def test_a_promotion_goes_to_the_worker_that_ran_its_rung_and_waits_for_it_while_it_is_live():
    core, storage, _ = _core()
    _screen(core, {"w-a": (0.9, 0.1), "w-b": (0.8, 0.2)})   # the top half of rung 0: row 0 (w-a), row 2 (w-b)
    own = _one(core, "w-b")
    assert storage.trial(own.trial_id).parent == 2 and own.duration_s == 3.0 and not own.from_start
    new = _one(core, "w-b")   # row 0 ranks first but w-a ran it and is live: w-b samples a new set
    assert storage.trial(new.trial_id).rung == 0 and storage.trial(new.trial_id).parent == -1
    theirs = _one(core, "w-a")
    assert storage.trial(theirs.trial_id).parent == 0 and not theirs.from_start


def test_a_promotion_whose_worker_fell_silent_goes_to_whoever_asks():
    core, storage, clock = _core()
    _screen(core, {"w-a": (0.9, 0.8), "w-b": (0.1, 0.2)})   # both of the top half ran on w-a
    assert storage.trial(_one(core, "w-b").trial_id).rung == 0          # w-a is live: its promotions wait
    clock.advance(LEASE_S + 1)
    taken = _one(core, "w-b")   # w-a said nothing for longer than a lease: w-b runs it from the start
    assert storage.trial(taken.trial_id).parent == 0 and not taken.from_start


def test_once_sampling_is_done_a_promotion_waits_for_no_one():
    core, storage, _ = _core(trials=4)
    _screen(core, {"w-a": (0.9, 0.8), "w-b": (0.1, 0.2)})
    taken = _one(core, "w-b")
    assert storage.trial(taken.trial_id).parent == 0


def test_with_continuation_off_the_order_is_the_plain_one_and_every_trial_starts_from_zero():
    core, storage, _ = _core()
    core.ladder.continue_rungs = False
    _screen(core, {"w-a": (0.9, 0.1)})
    given = ask(core, "w-b", 2).assignments   # the best of rung 0 first, though w-a ran it and is live
    assert storage.trial(given[0].trial_id).parent == 0 and storage.trial(given[1].trial_id).rung == 0
    assert all(a.from_start for a in given)
    # on, the same request waits for w-a and samples two new sets
    core, storage, _ = _core()
    _screen(core, {"w-a": (0.9, 0.1)})
    given = ask(core, "w-b", 2).assignments
    assert [storage.trial(a.trial_id).rung for a in given] == [0, 0] and not any(a.from_start for a in given)


def test_the_asker_chooses_among_the_promotable_rows_in_their_order():
    """Storage alone: rows 1 (0.9, w-a) and 5 (0.8, w-b) are the top third of six."""
    rungs = halving_ladder((1.0, 3.0), 3)
    st = _storage_with([])
    for tid, (obj, worker) in enumerate([(0.1, "w-a"), (0.9, "w-a"), (0.5, "w-b"), (0.7, "w-c"), (0.2, "w-b"),
                                         (0.8, "w-b")]):
        st.add_trial(tid, np.full(3, 0.5), np.zeros(3), "monte_carlo", -1, 0, 0, 1.0)
        st.finish_trial(tid, dataclasses.replace(_result(tid, obj), worker_id=worker), obj)
    live = Asker("w-c", lambda w: True)
    assert list(rungs.promotable(st, False)) == [1, 5]
    assert rungs.promotion(st) == 1 and rungs.promotion(st, asker=Asker("w-b", lambda w: True)) == 5
    assert rungs.promotion(st, asker=live) is None                        # both wait for their live workers
    assert rungs.promotion(st, asker=Asker("w-c", lambda w: w == "w-a")) == 5  # w-b is gone: 5 goes
    assert rungs.promotion(st, True, live) == 1                           # sampling done: the plain order


def test_an_audit_simulates_from_the_start_while_the_trial_it_checks_may_continue():
    config = build_run_config("audited", "sphere:3", seed=5)
    core, _ = new_run(config, SearchSettings(trials=4, sampler="random", audit=AuditPolicy(fraction=0.001)), None,
                      FakeClock())
    first = _one(core, "w1")
    assert not first.from_start
    [audit] = ask(core, "w2").assignments   # another identity audits the best: an independent re-run
    assert audit.trial_id == first.trial_id and audit.fidelity.task == "audit" and audit.from_start
