"""Peers that lie or misbehave: forged results, non-finite scores, oversized or malformed messages,
greedy requests and trials that keep killing their workers."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import pytest

from spinefarm.coordinator.scheduler import MAX_GRANT, Scheduler
from spinefarm.protocol import limits
from spinefarm.protocol.envelope import SCHEMA_VERSION, decode, encode
from spinefarm.protocol.errors import MessageError
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.states import TrialStatus
from spinefarm.protocol.submissions import Verdict
from tests.coordinator_tests.helpers import FakeClock, sphere_core
from tests.coordinator_tests.test_core import ask, assert_unchanged, res, snapshot, submit


def test_lease_ids_are_random_and_bound_to_the_worker_they_went_to():
    core, storage, _ = sphere_core(trials=30)
    mine = ask(core, "w1", n=4).assignments
    ids = [a.lease_id for a in mine]
    assert len(set(ids)) == 4 and max(ids) > 2**40  # 62 random bits, not a counter
    assert sorted(set(ids)) != list(range(min(ids), min(ids) + 4))
    a = mine[0]
    # w2 knows w1's id (liveliness tokens are public) and guesses lease ids around one it was given.
    theirs = ask(core, "w2", n=1).assignments[0]
    forged = [(theirs.lease_id + d, res(a, worker="w1", distance=1237.0)) for d in (-2, -1, 1, 2)]
    assert set(submit(core, forged, worker="w1").values()) == {Verdict.STALE}
    # Even the right lease id, sent under another worker's name, is refused.
    assert submit(core, [(a.lease_id, res(a, distance=1237.0))], worker="w2") == {a.trial_id: Verdict.STALE}
    assert core.status()["forged_results"] == 5
    assert storage.columns()["status"][a.trial_id] == b"waiting"
    assert submit(core, [(a.lease_id, res(a, distance=1.0))], worker="w1") == {a.trial_id: Verdict.STORED}
    assert core.status()["forged_results"] == 5


def test_a_late_result_of_an_expired_lease_is_stale_not_forged():
    core, _, clock = sphere_core(trials=10, lease_s=5.0)
    a = ask(core, "w1").assignments[0]
    clock.advance(6.0)
    core.tick()
    ask(core, "w2")  # the trial goes to w2
    assert submit(core, [(a.lease_id, res(a))], worker="w1") == {a.trial_id: Verdict.STALE}
    assert core.status()["forged_results"] == 0 and core.status()["dropped_results"]["stale"] == 1


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_non_finite_score_is_stored_as_a_failure_with_its_reason(bad):
    core, storage, _ = sphere_core(trials=10)
    a = ask(core).assignments[0]
    assert submit(core, [(a.lease_id, res(a, distance=bad))]) == {a.trial_id: Verdict.STORED}
    cols = storage.columns()
    assert cols["status"][a.trial_id] == b"failed"
    assert cols["reason"][a.trial_id].decode().startswith("non-finite score: distance_m=")
    assert storage.best_ids(1) == []


def test_one_request_cannot_take_the_run_and_batch_leases_follow_the_trial_time():
    core, _, _ = sphere_core(trials=500, lease_s=60.0)
    first = ask(core, "greedy", n=4096)
    assert len(first.assignments) == MAX_GRANT
    # asking again with nothing in hand says the first grant never arrived: the same trials, and no more
    grant = ask(core, "greedy", n=4096)
    assert [a.trial_id for a in grant.assignments] == [a.trial_id for a in first.assignments]
    assert core.scheduler.n_leased == MAX_GRANT
    # Once trials are measured (0.01 s each), a batch's last lease is lease_s plus a few trial times.
    submit(core, [(a.lease_id, TrialResult(TrialStatus.COMPLETE, "", 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.01, 1.0, a.seed,
                                           trial_id=a.trial_id)) for a in grant.assignments], worker="greedy")
    later = ask(core, "greedy", n=64).assignments
    assert max(a.lease_s for a in later) < 60.0 + 64 * 4 * 0.01 + 1e-6
    assert core.scheduler.n_leased == 64


def test_a_trial_that_keeps_losing_its_worker_is_stored_as_failed_after_three_tries():
    core, storage, clock = sphere_core(trials=5, lease_s=5.0)
    for i, how in enumerate(("lost", "expired", "lost")):
        (a,) = ask(core, f"w{i}").assignments
        assert a.trial_id == 0
        if how == "lost":
            core.worker_lost(f"w{i}")
        else:
            clock.advance(6.0)
            core.tick()
    cols = storage.columns()
    assert cols["status"][0] == b"failed"
    assert cols["reason"][0].decode() == "lost its worker 3 times (last: worker w2 vanished) on 3 workers: w0, w1, w2"
    assert ask(core, "w9").assignments[0].trial_id == 1  # the run goes on with the next trial


def test_a_trial_that_times_out_is_issued_again_only_to_workers_it_has_not_failed_on():
    core, storage, _ = sphere_core(trials=10, lease_s=5.0)
    for w in ("w0", "w1", "w2"):
        core.worker_seen(w)
    (a,) = ask(core, "w0").assignments
    for w in ("w0", "w1", "w2"):
        timeout = replace(res(a, worker=w), status=TrialStatus.FAILED, reason="timeout: no result within 1 s")
        assert submit(core, [(a.lease_id, timeout)], worker=w) == {a.trial_id: Verdict.REQUEUED}
        if w != "w2":
            assert a.trial_id not in [x.trial_id for x in ask(core, w, n=3).assignments]  # new trials instead
            (a,) = [x for x in ask(core, {"w0": "w1", "w1": "w2"}[w]).assignments if x.trial_id == a.trial_id]
    assert storage.columns()["reason"][a.trial_id].decode() == \
        "timeout: no result within 1 s (3 attempts) on 3 workers: w0, w1, w2"


def test_max_attempts_is_a_setting():
    s = Scheduler(FakeClock(0.0), lease_s=1.0, max_attempts=1)
    s.grant("w1", 1, iter([0, None]).__next__)
    s.worker_lost("w1")
    assert s.given_up == [(0, "lost its worker 1 times (last: worker w1 vanished) on 1 worker: w1")] and s.n_queued == 0


def envelope(body, kind="work_request") -> bytes:
    return json.dumps({"schema": SCHEMA_VERSION, "kind": kind, "body": body}).encode()


MALFORMED = {
    "deep nesting": b'{"schema":1,"kind":"work_request","body":' + b"[" * 100_000 + b"]" * 100_000 + b"}",
    "moderate nesting": envelope({"worker_id": "w", "capacity": 1, "x": json.loads("[" * 40 + "]" * 40)}),
    "5000-digit integer": envelope({"worker_id": "w", "capacity": int("9" * 4000)}).replace(b"9" * 4000, b"9" * 5000),
    "1e400": b'{"schema":1,"kind":"work_request","body":{"worker_id":"w","capacity":1e400}}',
    "NaN literal": b'{"schema":1,"kind":"work_request","body":{"worker_id":"w","capacity":NaN}}',
    "lone surrogate id": envelope({"worker_id": "\ud800", "capacity": 1}),
    "10 MB id": envelope({"worker_id": "w" * (10 * 1024 * 1024), "capacity": 1}),
    "long id": envelope({"worker_id": "w" * 65, "capacity": 1}),
    "id with a slash": envelope({"worker_id": "a/b", "capacity": 1}),
    "not UTF-8": b'{"schema":1,"kind":"work_request","body":{"worker_id":"\xff\xfe","capacity":1}}',
    "huge reason, no trial id": envelope({"worker_id": "w", "items": [{"lease_id": 1, "result": {
        "status": "complete", "reason": "x" * 5000, "distance_m": 1, "ntrt_distance_cm": 1, "speed_cm_s": 1,
        "work_j": 1, "cot": 1, "sim_time_s": 1, "wall_time_s": 1, "mass_kg": 1, "seed": 1}}]},
        kind="result_submission"),
    "string capacity": envelope({"worker_id": "w", "capacity": "4096"}),
    "huge verdict list": envelope({"worker_id": "w", "capacity": 1, "results": [1] * 5000}),
}


@pytest.mark.parametrize("name", sorted(MALFORMED))
def test_every_malformed_message_gets_an_error_reply_and_changes_nothing(name):
    core, storage, _ = sphere_core(trials=10)
    ask(core)
    before = snapshot(storage)
    payload = MALFORMED[name]
    handler = core.handle_results if b"result_submission" in payload[:60] else core.handle_work
    kind, body = decode(handler(payload))
    assert kind == "error" and body["code"] == "malformed_message", body
    assert len(body["message"]) < 400  # one line, never the whole payload
    assert_unchanged(before, storage)
    assert core.status()["rejected_messages"] == 1


def test_limits_in_isolation():
    with pytest.raises(MessageError, match="too large"):
        limits.loads(b" " * (limits.MAX_MESSAGE_BYTES + 1))
    assert limits.loads(b'{"a": [1, 2.5, "inf"]}') == {"a": [1, 2.5, "inf"]}
    assert decode(encode("x", {"d": math.inf}))[1]["d"] == math.inf  # our own encoding of inf still travels


def unreadable_item(a, reason: str = "x" * 5000) -> dict:
    """A submitted result whose trial and lease can be read but whose result cannot (a reason too long)."""
    return {"lease_id": a.lease_id, "result": {
        "status": "complete", "reason": reason, "distance_m": 1, "ntrt_distance_cm": 1, "speed_cm_s": 1,
        "work_j": 1, "cot": 1, "sim_time_s": 1, "wall_time_s": 1, "mass_kg": 1, "seed": a.seed,
        "trial_id": a.trial_id}}


def test_a_result_that_cannot_be_read_is_stored_as_failed_and_the_rest_of_its_batch_as_sent():
    """One unreadable result used to void its whole batch: the worker dropped them all and the trials ran
    again, the unreadable one for ever."""
    core, storage, _ = sphere_core(trials=10)
    a, b = ask(core, n=2).assignments
    good = res(b).to_dict()
    payload = envelope({"worker_id": "w1", "items": [unreadable_item(a), {"lease_id": b.lease_id, "result": good}]},
                       kind="result_submission")
    kind, body = decode(core.handle_results(payload))
    assert kind == "result_ack", body
    assert dict(body["verdicts"]) == {a.trial_id: "stored", b.trial_id: "stored"}
    cols = storage.columns()
    assert cols["status"][a.trial_id] == b"failed" and cols["status"][b.trial_id] == b"complete"
    reason = cols["reason"][a.trial_id].decode()
    assert reason.startswith("unreadable result: trial result field 'reason' is too long"), reason
    assert cols["seed"][a.trial_id] == a.seed
    # carried with a work request, the same
    c, = ask(core).assignments
    req = envelope({"worker_id": "w1", "capacity": 1, "results": [unreadable_item(c, reason=7)]})
    kind, body = decode(core.handle_work(req))
    assert kind == "work_grant" and dict(body["verdicts"]) == {c.trial_id: "stored"}, body
    assert storage.columns()["status"][c.trial_id] == b"failed"


def test_an_unreadable_result_quoting_a_lease_it_was_never_given_changes_nothing():
    core, storage, _ = sphere_core(trials=10)
    a, = ask(core).assignments
    before = snapshot(storage)
    forged = dict(unreadable_item(a), lease_id=a.lease_id + 1)
    kind, body = decode(core.handle_results(envelope({"worker_id": "w1", "items": [forged]},
                                                      kind="result_submission")))
    assert kind == "result_ack" and dict(body["verdicts"]) == {a.trial_id: "stale"}
    assert_unchanged(before, storage)
    assert core.status()["forged_results"] == 1
