"""The coordinator's Zenoh edge with real sessions over TCP on loopback (in one process)."""

from __future__ import annotations

import json
import threading
import time

import pytest
import zenoh

from spinefarm.coordinator.service import CoordinatorService, zenoh_config
from spinefarm.protocol import keys
from spinefarm.protocol.code_digest import code_digest
from spinefarm.protocol.envelope import decode, decode_message, encode_message
from spinefarm.protocol.submissions import ResultAck
from spinefarm.protocol.work import RunInfo, WorkGrant, WorkRequest
from spinefarm.storage.status import read_status
from spinefarm.worker.service.zenoh_worker import WorkerService, ZenohAccess
from tests.coordinator_tests.helpers import free_endpoint, sphere_core, wait_for

pytestmark = pytest.mark.integration


@pytest.fixture
def endpoint():
    return free_endpoint()


@pytest.fixture
def client(endpoint):
    sessions = []

    def open_client():
        s = zenoh.open(zenoh_config("client", connect=[endpoint]))
        sessions.append(s)
        return s
    yield open_client
    for s in sessions:
        s.close()


def query(session, key, payload=None):
    replies = [r.ok.payload.to_bytes() for r in session.get(key, payload=payload, timeout=5.0) if r.ok]
    assert len(replies) == 1, f"expected one reply on {key}, got {len(replies)}"
    return replies[0]


def start_workers(endpoint, run_id, n, batch=8):
    workers = [WorkerService(ZenohAccess([endpoint]), run_id=run_id, batch=batch, exit_when_done=True,
                             worker_id=f"w{i}") for i in range(n)]
    threads = [threading.Thread(target=w.run, daemon=True) for w in workers]
    for t in threads:
        t.start()
    return workers, threads


def test_two_workers_finish_a_run_and_every_trial_is_stored_once(endpoint, tmp_path):
    core, storage, _ = sphere_core(trials=300, clock=time.monotonic, out=tmp_path / "run.h5")
    service = CoordinatorService(core, storage, listen=[endpoint], status_file_for=tmp_path / "run.h5",
                                 flush_interval_s=0.1).start()
    try:
        workers, threads = start_workers(endpoint, core.run_id, 2)
        assert service.wait_done(30)
        for t in threads:
            t.join(10)
            assert not t.is_alive()
        assert sum(w.trials_run for w in workers) == 300
        assert all(w.trials_run > 0 for w in workers)
        cols = storage.columns()
        assert sorted(cols["trial_id"].tolist()) == list(range(300))
        assert set(cols["status"].tolist()) == {b"complete"}
        assert set(cols["worker_id"].tolist()) == {b"w0", b"w1"}
        assert {"monte_carlo", "gaussian"} == {p.decode() for p in cols["phase"]}
        wait_for(lambda: (read_status(tmp_path / "run.h5") or {}).get("trials_complete") == 300,
                 what="status file")
    finally:
        service.close()


def test_malformed_and_foreign_messages_are_answered_and_the_run_goes_on(endpoint, client):
    core, storage, _ = sphere_core(trials=20, clock=time.monotonic)
    service = CoordinatorService(core, storage, listen=[endpoint]).start()
    try:
        s = client()
        for payload in (None, b"\x00\x01junk", b'{"schema": 1, "kind": "work_request", "body": 3}',
                        json.dumps({"schema": 2, "kind": "work_request", "body": {}}).encode()):
            kind, body = decode(query(s, keys.work(core.run_id), payload))
            assert kind == "error" and body["code"] == "malformed_message"
            kind, body = decode(query(s, keys.results(core.run_id), payload))
            assert kind == "error" and body["code"] == "malformed_message"
        s.put(keys.work(core.run_id), b"a put, not a query")
        s.put(keys.results(core.run_id), b"{}")
        s.liveliness().declare_token("spinefarm/workers/x/y/z")  # a foreign token shape
        kind, _ = decode(query(s, f"{keys.run_prefix(core.run_id)}/config/0123456789abcdef"))
        assert kind == "error"
        assert storage.n_trials() == 0
        info = decode_message(query(s, keys.run_info(core.run_id)), RunInfo)
        assert info.config_hash == core.config_hash and not info.run_done
        start_workers(endpoint, core.run_id, 1)
        assert service.wait_done(20)
        assert storage.counts()["complete"] == 20
        assert core.rejected_messages >= 9
    finally:
        service.close()


def test_a_vanished_liveliness_token_reissues_its_leases_at_once(endpoint, client):
    core, storage, _ = sphere_core(trials=20, clock=time.monotonic, lease_s=3600)
    service = CoordinatorService(core, storage, listen=[endpoint]).start()
    try:
        s = client()
        token = s.liveliness().declare_token(keys.worker_token("ghost"))
        wait_for(lambda: "ghost" in core.scheduler.workers, what="liveliness PUT")
        grant = decode_message(query(s, keys.work(core.run_id), encode_message(_req("ghost", 3))),
                               WorkGrant)
        assert len(grant.assignments) == 3 and core.scheduler.n_leased == 3
        token.undeclare()
        wait_for(lambda: core.scheduler.n_queued == 3, what="re-issue after token loss")
        assert not core.scheduler.workers["ghost"].alive
        other = decode_message(query(s, keys.work(core.run_id), encode_message(_req("w2", 3))),
                               WorkGrant)
        assert [a.trial_id for a in other.assignments] == [a.trial_id for a in grant.assignments]
    finally:
        service.close()


def test_worker_discovers_the_run_without_being_told(endpoint):
    core, storage, _ = sphere_core(trials=30, clock=time.monotonic, run_id="discover-me")
    service = CoordinatorService(core, storage, listen=[endpoint]).start()
    try:
        w = WorkerService(ZenohAccess([endpoint]), batch=4, exit_when_done=True)
        t = threading.Thread(target=w.run, daemon=True)
        t.start()
        assert service.wait_done(20)
        t.join(10)
        assert not t.is_alive() and w.trials_run == 30
    finally:
        service.close()


def test_results_ack_over_zenoh_is_idempotent(endpoint, client):
    from spinefarm.protocol.results import TrialResult
    from spinefarm.protocol.states import TrialStatus
    from spinefarm.protocol.submissions import ResultSubmission, SubmittedResult

    core, storage, _ = sphere_core(trials=5, clock=time.monotonic)
    service = CoordinatorService(core, storage, listen=[endpoint]).start()
    try:
        s = client()
        grant = decode_message(query(s, keys.work(core.run_id), encode_message(_req("w1", 1))), WorkGrant)
        (a,) = grant.assignments
        r = TrialResult(TrialStatus.COMPLETE, "", 1.0, 0, 0, 0, 0, 1, 0, 1, a.seed, trial_id=a.trial_id)
        sub = encode_message(ResultSubmission("w1", (SubmittedResult(a.lease_id, r, coordinator=grant.coordinator),)))
        first = decode_message(query(s, keys.results(core.run_id), sub), ResultAck)
        second = decode_message(query(s, keys.results(core.run_id), sub), ResultAck)
        assert [v.value for _, v in first.verdicts + second.verdicts] == ["stored", "duplicate"]
        assert storage.counts()["complete"] == 1
    finally:
        service.close()


def _req(worker_id: str, n: int) -> WorkRequest:
    """A request as this install's workers send it (with their code's digest)."""
    return WorkRequest(worker_id, n, code_digest=code_digest())
