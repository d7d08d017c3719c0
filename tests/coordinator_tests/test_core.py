"""The coordinator core over real messages: grants, verdicts, malformed input, budget, resume."""

from __future__ import annotations

import json

import pytest

from spinefarm.coordinator.setup import build_core
from spinefarm.protocol.envelope import decode, decode_message, encode, encode_message
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.run import RunConfig
from spinefarm.protocol.states import TrialStatus
from spinefarm.protocol.submissions import ResultAck, ResultSubmission, SubmittedResult, Verdict
from spinefarm.protocol.work import RunInfo, WorkGrant, WorkRequest
from tests.coordinator_tests.helpers import sphere_core


def ask(core, worker="w1", n=1) -> WorkGrant:
    return decode_message(core.handle_work(encode_message(WorkRequest(worker, n))), WorkGrant)


def res(a, worker="w1", distance=1.0, seed=None) -> TrialResult:
    return TrialResult(TrialStatus.COMPLETE, "", distance, 0.0, 0.0, 0.0, 0.0, 1.0, 0.001, 1.0,
                       a.seed if seed is None else seed, trial_id=a.trial_id, worker_id=worker)


def submit(core, items, worker="w1") -> dict[int, Verdict]:
    sub = ResultSubmission(worker, tuple(SubmittedResult(lease, r) for lease, r in items))
    return dict(decode_message(core.handle_results(encode_message(sub)), ResultAck).verdicts)


def snapshot(storage):
    return {k: v.copy() for k, v in storage.columns().items()}


def assert_unchanged(before, storage):
    after = storage.columns()
    assert before.keys() == after.keys()
    for k in before:
        assert before[k].shape == after[k].shape
        assert (before[k].astype(str) == after[k].astype(str)).all(), k


def test_grant_carries_unit_vectors_seeds_and_the_config_hash():
    core, storage, _ = sphere_core()
    grant = ask(core, n=3)
    assert [a.trial_id for a in grant.assignments] == [0, 1, 2]
    assert grant.config_hash == core.config_hash and not grant.run_done
    a = grant.assignments[1]
    assert len(a.params_unit) == 4 and all(0 <= u <= 1 for u in a.params_unit)
    assert a.seed == storage.trial(1).seed
    assert a.lease_s == pytest.approx(20.0)  # second of the batch: 2 x lease_s
    config = decode_message(core.handle_config(core.config_hash), RunConfig)
    assert config.config_hash() == core.config_hash and len(config.space()) == 4


def test_results_are_stored_once_and_a_resend_is_a_duplicate():
    core, storage, _ = sphere_core()
    (a,) = ask(core).assignments
    assert submit(core, [(a.lease_id, res(a, distance=2.5))]) == {0: Verdict.STORED}
    assert submit(core, [(a.lease_id, res(a, distance=9.0))]) == {0: Verdict.DUPLICATE}
    rec = storage.trial(0)
    assert (rec.status, rec.distance_m, rec.objective, rec.worker_id) == ("complete", 2.5, 2.5, "w1")


def test_result_for_an_expired_lease_is_dropped_and_the_reissue_is_stored():
    core, storage, clock = sphere_core(lease_s=10.0)
    (a,) = ask(core, "w1").assignments
    clock.advance(10.0)
    assert core.tick() == [0]
    (b,) = ask(core, "w2").assignments
    assert b.trial_id == 0 and b.lease_id != a.lease_id
    assert submit(core, [(a.lease_id, res(a, "w1", 5.0))], "w1") == {0: Verdict.STALE}
    assert storage.trial(0).status == "waiting"
    assert submit(core, [(b.lease_id, res(b, "w2", 1.0))], "w2") == {0: Verdict.STORED}
    assert storage.trial(0).distance_m == 1.0 and storage.trial(0).worker_id == "w2"
    assert core.status()["dropped_results"]["stale"] == 1


def test_lost_worker_trials_go_to_the_next_worker_and_its_late_results_are_dropped():
    core, storage, _ = sphere_core()
    grant = ask(core, "w1", 2)
    assert core.worker_lost("w1") == [0, 1]
    again = ask(core, "w2", 3)
    assert [a.trial_id for a in again.assignments] == [0, 1, 2]
    late = submit(core, [(a.lease_id, res(a, "w1")) for a in grant.assignments], "w1")
    assert late == {0: Verdict.STALE, 1: Verdict.STALE}
    assert storage.counts()["complete"] == 0


def test_trials_of_a_grant_whose_reply_never_arrived_are_issued_again_at_the_next_request():
    core, storage, _ = sphere_core(lease_s=60.0)
    lost = ask(core, "w1", n=2).assignments  # the worker's query timed out before this reply came
    again = ask(core, "w1", n=3).assignments  # it asks again with nothing in hand, long before the lease ends
    assert [a.trial_id for a in again] == [a.trial_id for a in lost] + [2]
    assert {a.lease_id for a in again}.isdisjoint(a.lease_id for a in lost)
    assert core.scheduler.n_leased == 3
    old, new = lost[0], again[0]
    assert submit(core, [(old.lease_id, res(old))]) == {0: Verdict.STALE}
    assert submit(core, [(new.lease_id, res(new))]) == {0: Verdict.STORED}
    # results riding along settle their trials first: nothing is taken back, the next trials come
    rest = [(a.lease_id, res(a)) for a in again[1:]]
    carried = tuple(SubmittedResult(lease, r) for lease, r in rest)
    grant = decode_message(core.handle_work(encode_message(WorkRequest("w1", 2, carried))), WorkGrant)
    assert [a.trial_id for a in grant.assignments] == [3, 4]
    assert all(storage.trial(t).status == "complete" for t in (0, 1, 2))


def test_unknown_trial_wrong_seed_and_foreign_lease_are_dropped():
    core, storage, _ = sphere_core()
    (a,) = ask(core).assignments
    ghost = TrialResult(TrialStatus.COMPLETE, "", 1.0, 0, 0, 0, 0, 1, 0, 1, 0, trial_id=999)
    assert submit(core, [(a.lease_id, ghost)]) == {999: Verdict.UNKNOWN}
    assert submit(core, [(a.lease_id, res(a, seed=a.seed + 1))]) == {0: Verdict.INVALID}
    assert submit(core, [(a.lease_id + 77, res(a))]) == {0: Verdict.STALE}
    assert submit(core, [(a.lease_id, res(a, "intruder"))], "intruder") == {0: Verdict.STALE}
    assert storage.counts() == {"waiting": 1, "complete": 0, "failed": 0}


@pytest.mark.parametrize("payload", [
    b"", b"\xff\xfe garbage", b"[1, 2]", b'{"schema": 1}',
    json.dumps({"schema": 999, "kind": "work_request", "body": {}}).encode(),
    encode("result_submission", {"worker_id": "w1", "items": []}),
    encode("work_request", {"worker_id": "w1", "capacity": 0}),
    encode("work_request", {"worker_id": "w1", "capacity": True}),
    encode("work_request", {"worker_id": "w1", "capacity": 10**9}),
    encode("work_request", {"worker": "w1"}),
])
def test_malformed_work_requests_get_an_error_and_change_nothing(payload):
    core, storage, _ = sphere_core()
    ask(core, n=2)
    before = snapshot(storage)
    kind, body = decode(core.handle_work(payload))
    assert kind == "error" and body["code"] == "malformed_message"
    assert "received" in body["message"] and "expected" in body["message"]
    assert_unchanged(before, storage)
    assert core.rejected_messages == 1


# Results that name no trial: nothing to attribute them to (one that names its trial and lease is stored as
# failed instead, test_hostile_peers.py)
@pytest.mark.parametrize("items", [
    "not a list",
    [{"lease_id": 1}],
    [{"lease_id": 1, "result": {"status": "complete"}}],
    [{"lease_id": 1, "result": {"status": "exploded", "reason": "", "distance_m": 1, "ntrt_distance_cm": 0,
                                "speed_cm_s": 0, "work_j": 0, "cot": 0, "sim_time_s": 0, "wall_time_s": 0,
                                "mass_kg": 1, "seed": 0}}],
    [{"lease_id": 1, "result": {"status": "complete", "reason": "", "distance_m": "far", "ntrt_distance_cm": 0,
                                "speed_cm_s": 0, "work_j": 0, "cot": 0, "sim_time_s": 0, "wall_time_s": 0,
                                "mass_kg": 1, "seed": 0, "trial_id": "0"}}],
    [{"lease_id": 1, "result": {"status": "complete", "reason": "", "distance_m": 1.0, "ntrt_distance_cm": 0,
                                "speed_cm_s": 0, "work_j": 0, "cot": 0, "sim_time_s": 0, "wall_time_s": 0,
                                "mass_kg": 1, "seed": 0}}],
])
def test_malformed_result_submissions_get_an_error_and_change_nothing(items):
    core, storage, _ = sphere_core()
    ask(core, n=2)
    before = snapshot(storage)
    kind, body = decode(core.handle_results(encode("result_submission", {"worker_id": "w1", "items": items})))
    assert kind == "error" and body["code"] == "malformed_message"
    assert_unchanged(before, storage)


def test_nan_scores_are_stored_but_never_best():
    core, storage, _ = sphere_core()
    a, b = ask(core, n=2).assignments
    assert submit(core, [(a.lease_id, res(a, distance=float("nan"))), (b.lease_id, res(b, distance=0.5))]) == {
        0: Verdict.STORED, 1: Verdict.STORED}
    assert storage.best_ids(2) == [1]


def test_budget_is_met_exactly_then_the_run_says_done():
    core, storage, _ = sphere_core(trials=5)
    grant = ask(core, n=10)
    assert len(grant.assignments) == 5
    assert ask(core, "w2", 3).assignments == () and ask(core, "w2").retry_after_s > 0
    submit(core, [(a.lease_id, res(a)) for a in grant.assignments])
    assert core.done and ask(core).run_done
    assert decode_message(core.run_info(), RunInfo).run_done
    assert storage.n_trials() == 5 and storage.counts()["complete"] == 5


def test_a_done_run_waits_for_workers_gone_within_a_lease_until_they_hear_done():
    core, _, clock = sphere_core(trials=2, lease_s=10.0)
    grant = ask(core, "w1", n=2)
    ask(core, "frozen")
    core.worker_lost("frozen")  # its token vanished (frozen, restarting or cut off)
    clock.advance(3.0)
    submit(core, [(a.lease_id, res(a)) for a in grant.assignments])
    assert core.done and ask(core, "w1").run_done
    assert not core.workers_released()  # it may be back any moment and would never hear it
    assert ask(core, "frozen").run_done and core.workers_released()
    core, _, clock = sphere_core(trials=1, lease_s=10.0)
    ask(core, "gone")
    core.worker_lost("gone")
    grant = ask(core, "w1")
    submit(core, [(a.lease_id, res(a)) for a in grant.assignments])
    clock.advance(10.5)  # gone longer than a lease: not waited for
    assert ask(core, "w1").run_done and core.workers_released()


def test_unknown_config_hash_is_an_error():
    core, _, _ = sphere_core()
    kind, body = decode(core.handle_config("0" * 16))
    assert kind == "error" and core.config_hash in body["message"]


def test_rebuilt_core_reissues_waiting_trials_first_and_continues_numbering():
    core, storage, clock = sphere_core(trials=10)
    grant = ask(core, n=4)
    submit(core, [(a.lease_id, res(a)) for a in grant.assignments[:2]])
    again = build_core(storage, clock)  # what resume does after reading the file back
    ids = [a.trial_id for a in ask(again, "w9", 4).assignments]
    assert ids == [2, 3, 4, 5]
    assert again.study.n_finished == 2


def test_status_reports_counts_rate_and_workers():
    core, _, clock = sphere_core(trials=10)
    grant = ask(core, n=4)
    clock.advance(2.0)
    submit(core, [(a.lease_id, res(a)) for a in grant.assignments[:2]])
    st = core.status()
    assert (st["trials_complete"], st["trials_leased"], st["trials_queued"]) == (2, 2, 6)
    assert st["rate_trials_s"] == pytest.approx(1.0)
    assert st["eta_s"] == pytest.approx(8.0)
    assert [w["worker_id"] for w in st["workers"]] == ["w1"]


def test_results_can_ride_along_with_the_next_work_request():
    core, storage, _ = sphere_core(trials=3)
    first = ask(core, n=2).assignments
    carried = tuple(SubmittedResult(a.lease_id, res(a, distance=1.5)) for a in first)
    grant = decode_message(core.handle_work(encode_message(WorkRequest("w1", 2, carried))), WorkGrant)
    assert dict(grant.verdicts) == {0: Verdict.STORED, 1: Verdict.STORED}
    assert [a.trial_id for a in grant.assignments] == [2]
    (last,) = grant.assignments
    final = WorkRequest("w1", 1, (SubmittedResult(last.lease_id, res(last)),))
    done = decode_message(core.handle_work(encode_message(final)), WorkGrant)
    assert done.run_done and dict(done.verdicts) == {2: Verdict.STORED}  # settled before "done"
    assert storage.counts()["complete"] == 3


def test_malformed_carried_results_refuse_the_whole_request():
    core, storage, _ = sphere_core()
    ask(core, n=1)
    before = snapshot(storage)
    bad = encode("work_request", {"worker_id": "w1", "capacity": 1, "results": [{"lease_id": 1}]})
    kind, body = decode(core.handle_work(bad))
    assert kind == "error" and "result" in body["message"]
    assert_unchanged(before, storage)


def test_only_a_worker_holding_this_runs_work_can_stop_it_with_a_problem():
    from spinefarm.protocol.run import WorkerProblem

    core, _, _ = sphere_core(5)
    forged = WorkerProblem("w9", "nothing builds here", 0, 12345)
    kind, body = decode(core.handle_problem(encode_message(forged)))
    assert kind == "error" and "no lease" in body["message"]
    assert core.failure is None and core.status()["state"] == "running"
    a = ask(core, "w1", 1).assignments[0]
    genuine = WorkerProblem("w1", "engine 'mujoco' is not installed", a.trial_id, a.lease_id)
    assert decode(core.handle_problem(encode_message(genuine)))[0] == "ack"
    assert "w1 cannot serve" in core.failure and core.status()["state"] == "failed"


def test_a_worker_that_cannot_serve_a_run_others_serve_is_left_out_and_the_run_goes_on():
    """One machine with an old install or without an engine must not stop a search its peers serve."""
    from spinefarm.protocol.run import WorkerProblem

    core, _, _ = sphere_core(20)
    a = ask(core, "w2", 1).assignments[0]
    assert submit(core, [(a.lease_id, res(a, worker="w2"))], worker="w2")[a.trial_id] == Verdict.STORED
    held = ask(core, "w1", 2).assignments
    problem = WorkerProblem("w1", "engine 'mujoco' is not installed", held[0].trial_id, held[0].lease_id)
    assert decode(core.handle_problem(encode_message(problem)))[0] == "ack"
    st = core.status()
    assert core.failure is None and st["state"] == "running"
    assert st["unservable_workers"] == {"w1": "engine 'mujoco' is not installed"}
    assert ask(core, "w1", 4).assignments == ()  # no more work for it
    again = ask(core, "w2", 2).assignments  # what it held goes to the others first
    assert [x.trial_id for x in again] == [x.trial_id for x in held]
    assert [x.params_unit for x in again] == [x.params_unit for x in held]


@pytest.mark.parametrize(("alive", "retry_s"), [(10, 0.5), (200, 2.0), (500, 5.0)])
def test_idle_workers_are_told_to_wait_longer_the_more_of_them_there_are(alive, retry_s):
    """An idle worker waits max(0.5 s, live workers / 100 per s): together they ask about 100 times a second."""
    core, _, _ = sphere_core(trials=1)
    for i in range(alive):
        core.worker_seen(f"w{i}")
    assert len(ask(core, "w0").assignments) == 1  # the whole budget is leased: nothing left for the others
    assert ask(core, "w1").retry_after_s == pytest.approx(retry_s)
