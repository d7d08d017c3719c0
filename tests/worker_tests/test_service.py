"""The worker loop against a real coordinator over Zenoh on loopback."""

from __future__ import annotations

import json
import logging
import random
import threading
import time

import numpy as np
import pytest

from spinefarm.coordinator.service import CoordinatorService
from spinefarm.protocol.errors import ConfigError
from spinefarm.protocol.run import RunConfig
from spinefarm.protocol.states import TrialStatus
from spinefarm.protocol.work import TrialAssignment
from spinefarm.worker.service.zenoh_worker import (
    Backoff,
    WorkerService,
    WorkerTimings,
    ZenohAccess,
    build_evaluator,
    default_worker_id,
    sphere_result,
)
from tests.coordinator_tests.helpers import free_endpoint, sphere_core, wait_for

pytestmark = pytest.mark.integration


def sphere_config(n: int = 3, delay_s: float | None = None) -> RunConfig:
    from spinefarm.coordinator.problem import build_run_config

    return build_run_config("r", f"sphere:{n}", duration_s=delay_s)


def test_sphere_scores_peak_at_the_optimum():
    space = sphere_config().space()
    best = sphere_result(space, TrialAssignment(0, 1, tuple(space.to_unit(np.full(3, 0.3))), 5, 1.0))
    off = sphere_result(space, TrialAssignment(1, 1, (0.0, 0.0, 0.0), 5, 1.0))
    assert best.status == TrialStatus.COMPLETE and best.distance_m == pytest.approx(3.0)
    assert off.distance_m < best.distance_m and best.seed == 5


def test_bad_vector_becomes_a_failed_result_naming_the_problem():
    w = WorkerService(ZenohAccess(["tcp/127.0.0.1:9"]), worker_id="w-bad")
    evaluate = build_evaluator(sphere_config())
    r = w._run_one(evaluate, TrialAssignment(4, 9, (0.5, 0.5), 11, 1.0))
    assert r.status == TrialStatus.FAILED and r.trial_id == 4 and r.worker_id == "w-bad" and r.seed == 11
    assert "wrong length" in r.reason and "3 values" in r.reason
    r = w._run_one(evaluate, TrialAssignment(5, 9, (0.5, float("nan"), 0.5), 11, 1.0))
    assert r.status == TrialStatus.FAILED and "non-finite" in r.reason


def test_backoff_doubles_up_to_a_cap_and_resets():
    b = Backoff(0.1, 0.5)
    steps = (0.1, 0.2, 0.4, 0.5, 0.5)   # each wait is drawn from the upper half of its step
    assert all(s / 2 <= b.next() <= s for s in steps)
    b.reset()
    assert 0.05 <= b.next() <= 0.1


def test_workers_failing_at_the_same_moment_do_not_ask_again_in_step():
    """500 workers whose queries all failed at once (a dead coordinator's session dropped by the router): by
    their 10th retry (~11 s on) no 100 ms holds more than 100 of them (in step, all 500 would share one; the
    draws' spread is about 0.64 s, so about 31 share the busiest 100 ms)."""
    asks = np.array([sum(b.next() for _ in range(10)) for b in (Backoff(rng=random.Random(i)) for i in range(500))])
    asks.sort()
    busiest = max(int(np.searchsorted(asks, t + 0.1) - i) for i, t in enumerate(asks))
    assert busiest <= 100


def test_default_worker_ids_are_valid_and_distinct():
    from spinefarm.protocol.keys import check_worker_id

    a, b = default_worker_id(), default_worker_id()
    assert a != b and check_worker_id(a) == a


def test_worker_waits_for_an_absent_coordinator_then_serves_it():
    endpoint = free_endpoint()
    core, storage, _ = sphere_core(trials=40, clock=time.monotonic)
    w = WorkerService(ZenohAccess([endpoint]), run_id=core.run_id, batch=8, exit_when_done=True)
    t = threading.Thread(target=w.run, daemon=True)
    t.start()
    t.join(0.3)
    assert t.is_alive() and w.trials_run == 0  # nothing to reach yet: it keeps retrying
    service = CoordinatorService(core, storage, listen=[endpoint]).start()
    try:
        assert service.wait_done(30)
        t.join(10)
        assert not t.is_alive() and w.trials_run == 40
    finally:
        service.close()


def test_results_are_resent_until_the_coordinator_acknowledges_them():
    endpoint = free_endpoint()
    # Trials take a while (stand-in for physics) so the coordinator can vanish mid-batch.
    core, storage, _ = sphere_core(trials=3, clock=time.monotonic, morphology="sphere:2", duration_s=0.3)
    first = CoordinatorService(core, storage, listen=[endpoint]).start()
    # No result is handed in mid-batch (submit interval 60 s): they ride along with the next work request.
    w = WorkerService(ZenohAccess([endpoint]), run_id=core.run_id, batch=3, exit_when_done=True,
                      timings=WorkerTimings(query_timeout_s=1.0, submit_interval_s=60.0))
    t = threading.Thread(target=w.run, daemon=True)
    t.start()
    # Closing once the batch is leased raced the worker's fetch of the run's config (it then had leases it
    # could not run): close once a trial has run, so the worker holds the config and the rest of its batch.
    wait_for(lambda: core.scheduler.n_leased == 3 and w.trials_run >= 1, what="the batch to be leased and started")
    first.close()  # gone before any result could be returned
    wait_for(lambda: w.trials_run == 3, what="the worker to finish its batch")
    assert storage.counts()["complete"] == 0
    second = CoordinatorService(core, storage, listen=[endpoint]).start()
    try:
        assert second.wait_done(30)
        t.join(10)
        assert not t.is_alive()
        assert storage.counts() == {"waiting": 0, "complete": 3, "failed": 0}
        assert w.trials_run == 3  # nothing was run twice: the results were resent
    finally:
        second.close()


def test_auto_batch_follows_the_mean_trial_time():
    from spinefarm.worker.service.zenoh_worker import BatchSizer

    auto = BatchSizer(None, target_s=0.5, max_batch=64)
    assert auto.size() == 1  # nothing measured yet: one trial
    auto.observe(2.0)
    assert auto.size() == 1  # physics-like trials: one at a time
    for _ in range(60):
        auto.observe(1e-5)
    assert auto.size() == 64  # microsecond trials: capped large batches
    assert BatchSizer(7).size() == 7
    with pytest.raises(Exception, match="batch out of range"):
        WorkerService(ZenohAccess(["tcp/127.0.0.1:9"]), batch=0)


def test_bad_worker_waits_name_the_flag_and_the_value(capsys):
    for kwargs, flag in (({"coordinator_timeout_s": 0.0}, "--coordinator-timeout"),
                         ({"min_trial_limit_s": -1.0}, "--min-trial-limit")):
        with pytest.raises(ConfigError, match=flag) as err:
            WorkerTimings(**kwargs)
        assert str(next(iter(kwargs.values()))) in str(err.value)
    with pytest.raises(ConfigError, match="query timeout"):
        WorkerTimings(query_timeout_s=float("nan"))
    from spinefarm.cli.main import main

    assert main(["worker", "--connect", "tcp/127.0.0.1:9", "--min-trial-limit", "0"]) != 0
    assert "--min-trial-limit" in capsys.readouterr().err


class HandRolledCoordinator:
    """A minimal peer speaking the protocol over real Zenoh: grants one trial, then says done."""

    def __init__(self, endpoint: str, config: RunConfig, refuse_results: bool, served: RunConfig | None = None) -> None:
        """served: the config its config queryable answers with (default: the run's)."""
        import zenoh

        from spinefarm.coordinator.service import zenoh_config
        from spinefarm.protocol import keys
        from spinefarm.protocol.envelope import encode, encode_message
        from spinefarm.protocol.work import RunInfo, TrialAssignment, WorkGrant

        self.config, self.granted, self.submissions = config, False, 0
        h = config.config_hash()
        run = config.run_id

        def work(q):
            with q:
                done = self.granted
                a = () if done else (TrialAssignment(0, 1, (0.5,) * len(config.param_space), 3, 60.0),)
                self.granted = True
                q.reply(q.key_expr, encode_message(WorkGrant(run, h, a, 0.05, done)))

        def results(q):
            with q:
                self.submissions += 1
                q.reply(q.key_expr, encode("error", {"code": "malformed_message", "message": "no"})
                        if refuse_results else b"")

        def cfg(q):
            with q:
                q.reply(q.key_expr, encode_message(served or config))

        def info(q):
            with q:
                q.reply(q.key_expr, encode_message(RunInfo(run, h, 1, False)))

        self.session = zenoh.open(zenoh_config("router", [endpoint]))
        self.entities = [self.session.declare_queryable(keys.work(run), work),
                         self.session.declare_queryable(keys.results(run), results),
                         self.session.declare_queryable(keys.config(run, h), cfg),
                         self.session.declare_queryable(keys.run_info(run), info)]

    def close(self) -> None:
        self.session.close()


def run_worker_against(peer_config: RunConfig, refuse_results: bool, served: RunConfig | None = None):
    endpoint = free_endpoint()
    peer = HandRolledCoordinator(endpoint, peer_config, refuse_results, served)
    w = WorkerService(ZenohAccess([endpoint]), run_id=peer_config.run_id, exit_when_done=True,
                      timings=WorkerTimings(query_timeout_s=1.0))
    t = threading.Thread(target=w.run, daemon=True)
    try:
        t.start()
        t.join(20)
        assert not t.is_alive(), "the worker got stuck"
    finally:
        peer.close()
    return w, peer


def test_refused_results_are_dropped_not_resent_forever():
    w, peer = run_worker_against(sphere_config(), refuse_results=True)
    assert w.trials_run == 1 and peer.submissions == 1


def test_a_run_this_worker_cannot_serve_does_not_crash_it():
    from dataclasses import replace

    config = replace(sphere_config(), morphology="no-such-robot")
    w, _ = run_worker_against(config, refuse_results=False)
    assert w.trials_run == 0


def test_a_grant_whose_run_config_does_not_come_is_not_run_and_the_worker_says_why(caplog):
    """The coordinator answers the config query with another config (a stand-in for one that did not come): the
    worker runs nothing and says so in one line, naming the hash it received and the one it expected."""
    from dataclasses import replace

    config = sphere_config()
    other = replace(config, seed=config.seed + 1)
    caplog.set_level(logging.WARNING, logger="spinefarm.worker")
    w, _ = run_worker_against(config, refuse_results=False, served=other)
    lines = [r.getMessage() for r in caplog.records if "cannot run the trials granted" in r.getMessage()]
    assert w.trials_run == 0 and len(lines) == 1
    assert "\n" not in lines[0] and other.config_hash() in lines[0] and config.config_hash() in lines[0]


def test_zenoh_json5_config_file_is_passed_through(tmp_path):
    endpoint = free_endpoint()
    conf = tmp_path / "zenoh.json5"
    quoted = json.dumps([endpoint])
    conf.write_text(f"{{\n  // endpoints come from this file only\n  connect: {{ endpoints: {quoted} }},\n}}\n")
    core, storage, _ = sphere_core(trials=10, clock=time.monotonic)
    service = CoordinatorService(core, storage, listen=[endpoint]).start()
    try:
        w = WorkerService(ZenohAccess(config_file=conf), run_id=core.run_id, exit_when_done=True)
        t = threading.Thread(target=w.run, daemon=True)
        t.start()
        assert service.wait_done(20)
        t.join(10)
        assert w.trials_run == 10
    finally:
        service.close()


def test_unreadable_zenoh_config_is_a_clear_error(tmp_path):

    bad = tmp_path / "bad.json5"
    bad.write_text("{ this is not json5 ")
    with pytest.raises(ConfigError, match="cannot read Zenoh config"):
        WorkerService(ZenohAccess(config_file=bad))
    with pytest.raises(ConfigError, match="cannot read Zenoh config"):
        WorkerService(ZenohAccess(config_file=tmp_path / "missing.json5"))


def test_a_worker_follows_the_coordinator_it_served_when_two_answer_for_its_run():
    """Two coordinators answering for one run (a copy started while the original was cut off): the worker keeps
    the holder it served, whichever answers first; with only one answering it goes with that one (a restart)."""
    from spinefarm.protocol.work import WorkGrant

    w = WorkerService(ZenohAccess(), run_id="r1", worker_id="w1")
    original, copy = (WorkGrant("r1", "ab12cd34", (), 0.5, run_done, coordinator=c)
                      for run_done, c in ((False, "100-aaa"), (True, "200-bbb")))
    assert w._holder_grant("r1", [original]) is original
    assert w._holder_grant("r1", [copy, original]) is original  # the copy's "done" is not followed
    restarted = WorkGrant("r1", "ab12cd34", (), 0.5, False, coordinator="300-ccc")
    assert w._holder_grant("r1", [restarted]) is restarted
    assert w._holder_grant("r1", [original, restarted]) is restarted


def test_a_verdict_settles_a_result_only_from_the_instance_that_leased_it_or_the_one_served_now():
    """A copy answering for the run cannot settle (say "stale" to) results leased by the holder, which then go
    unstored; once the worker serves another instance (the holder restarted), that one's verdicts settle them."""
    from spinefarm.protocol.results import TrialResult
    from spinefarm.protocol.submissions import SubmittedResult, Verdict
    from spinefarm.protocol.work import WorkGrant

    w = WorkerService(ZenohAccess(), run_id="r1", worker_id="w1")
    w._holder_grant("r1", [WorkGrant("r1", "ab12cd34", (), 0.5, False, coordinator="100-aaa")])
    w._pending["r1"] = {t: SubmittedResult(t, TrialResult.failed("x", t, trial_id=t), coordinator="100-aaa")
                        for t in (3, 5, 7)}
    w._apply("r1", ((3, Verdict.STALE), (5, Verdict.STALE)), "200-bbb")   # the copy's verdicts
    assert sorted(w._pending["r1"]) == [3, 5, 7]
    w._apply("r1", ((3, Verdict.STORED),), "100-aaa")   # the holder's
    assert sorted(w._pending["r1"]) == [5, 7]
    w._holder_grant("r1", [WorkGrant("r1", "ab12cd34", (), 0.5, False, coordinator="300-ccc")])   # a restart
    w._apply("r1", ((5, Verdict.STALE),), "300-ccc")
    assert sorted(w._pending["r1"]) == [7]


def test_results_whose_query_times_out_are_kept_and_sent_again_not_dropped():
    """A coordinator busy past the worker's query timeout answers nothing: Zenoh's "Timeout" error reply is no
    refusal, so the results stay pending and go again (before, the worker dropped them as refused)."""
    import zenoh

    from spinefarm.protocol import keys
    from spinefarm.protocol.envelope import encode_message
    from spinefarm.protocol.results import TrialResult
    from spinefarm.protocol.submissions import SubmittedResult
    from spinefarm.protocol.work import WorkGrant, WorkRequest

    endpoint = free_endpoint()
    core, storage, _ = sphere_core(trials=4, clock=time.monotonic, lease_s=3600)
    service = CoordinatorService(core, storage, listen=[endpoint]).start()
    w = WorkerService(ZenohAccess([endpoint]), run_id=core.run_id, worker_id="w1", isolate=False,
                      timings=WorkerTimings(query_timeout_s=0.5))
    session = zenoh.open(w.access.config())
    try:
        ask = encode_message(WorkRequest("w1", 2, code_digest=w.code_digest))
        [grant] = wait_for(lambda: w._query(session, keys.work(core.run_id), ask, WorkGrant)[0], poll_s=0.2,
                           what="a grant")
        w._holder_grant(core.run_id, [grant])
        w._pending[core.run_id] = {a.trial_id: SubmittedResult(a.lease_id, TrialResult(
            TrialStatus.COMPLETE, "", 1.0 + a.trial_id, 0, 0, 0, 0, 1, 0, 1, a.seed, trial_id=a.trial_id,
            worker_id="w1"), coordinator=grant.coordinator) for a in grant.assignments}
        with core.lock:   # the coordinator is busy for longer than the worker's 0.5 s query timeout
            assert w._submit(session) is False
        assert sorted(w._pending[core.run_id]) == sorted(a.trial_id for a in grant.assignments)
        wait_for(lambda: w._submit(session), poll_s=0.2, what="the results acknowledged once it answers")
        assert storage.counts()["complete"] == 2
    finally:
        session.close()
        service.close()
