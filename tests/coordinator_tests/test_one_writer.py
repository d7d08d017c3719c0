"""One writer per run and one code per run, over real Zenoh: a copy of a live run's file resumed on the same
network is refused while the original holds the run (which finishes its exact budget and says who claimed it),
and a worker of other simulating code gets no work and has nothing stored."""

from __future__ import annotations

import shutil
import time

import numpy as np
import zenoh

from spinefarm.coordinator.service import CoordinatorService, zenoh_config
from spinefarm.protocol import keys
from spinefarm.protocol.code_digest import code_digest
from spinefarm.protocol.envelope import decode_message, encode_message
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.states import TrialStatus
from spinefarm.protocol.submissions import ResultAck, ResultSubmission, SubmittedResult, Verdict
from spinefarm.protocol.work import WorkGrant, WorkRequest
from spinefarm.storage.hdf5 import Hdf5Storage
from spinefarm.storage.status import read_status
from tests.coordinator_tests.helpers import free_endpoint, sphere_core, wait_for
from tests.coordinator_tests.procs import STARTED, coordinator, spinefarm, stop, wait_status, worker


def _log_of(proc) -> str:
    [path] = [p for _, p, q in STARTED if q is proc]
    return path.read_text(errors="replace")


def test_a_copy_of_a_live_run_resumed_on_the_same_network_is_refused_and_the_original_finishes(tmp_path):
    ep, out, copy = free_endpoint(), tmp_path / "run.h5", tmp_path / "copy.h5"
    # long enough (300 trials of 50 ms on 2 workers, 7.5 s at least) to be running when its copy starts
    original = coordinator(ep, out, "sphere:3", "--trials", "300", "--duration", "0.05", "--run-id", "held")
    workers = [worker(ep, "held", f"w{i}") for i in range(2)]
    claimant = None
    try:
        wait_status(out, lambda st: st["trials_complete"] >= 10, "10 trials stored")
        shutil.copy(out, copy)
        claimant = spinefarm("coordinator", "--resume", str(copy), "--connect", ep, "--api-port", "-1", "--quiet")
        assert claimant.wait(60) != 0
        said = _log_of(claimant).strip().splitlines()[-1]
        assert "run held is already held by another coordinator on this network" in said, said
        assert original.wait(120) == 0  # not stopped by the copy: it ran to its end
        with Hdf5Storage.open_read(out) as s:
            status = s.columns()["status"]
            assert len(status) == 300 and int(np.count_nonzero(status == b"complete")) == 300  # the exact budget
        claims = read_status(out)["claimed_by"]
        assert len(claims) == 1 and next(iter(claims.values())).startswith("refused")
        assert "claims run held" in _log_of(original)
    finally:
        stop(original, *workers, *([claimant] if claimant else []))


def _ask(session: zenoh.Session, run_id: str, req: WorkRequest) -> WorkGrant:
    [reply] = list(session.get(keys.work(run_id), payload=encode_message(req), timeout=5))
    return decode_message(reply.ok.payload.to_bytes(), WorkGrant)


def test_a_worker_announcing_other_simulating_code_gets_no_work_and_nothing_of_it_is_stored(tmp_path):
    ep = free_endpoint()
    core, storage, _ = sphere_core(trials=20, lease_s=3600, clock=time.monotonic)
    service = CoordinatorService(core, storage, listen=[ep]).start()
    s = zenoh.open(zenoh_config("client", connect=[ep]))
    try:
        old = "0" * 64  # an install of other code: another digest
        assert _ask(s, core.run_id, WorkRequest("old", 4, code_digest=old)).assignments == ()
        assert _ask(s, core.run_id, WorkRequest("older", 4)).assignments == ()  # one that says no digest at all
        unservable = core.status()["unservable_workers"]
        assert set(unservable) == {"old", "older"}
        assert "runs other simulating code: digest 000000000000" in unservable["old"]
        assert "no code digest" in unservable["older"]
        # the same install's digest gets work; a result sent under the old worker's id for its lease is refused
        grant = _ask(s, core.run_id, WorkRequest("new", 2, code_digest=code_digest()))
        assert len(grant.assignments) == 2 and grant.coordinator == core.holder
        a = grant.assignments[0]
        r = TrialResult(TrialStatus.COMPLETE, "", 1.0, 0, 0, 0, 0, 1, 0, 1, a.seed, trial_id=a.trial_id)
        sub = ResultSubmission("old", (SubmittedResult(a.lease_id, r, coordinator=grant.coordinator),))
        [reply] = list(s.get(keys.results(core.run_id), payload=encode_message(sub), timeout=5))
        assert decode_message(reply.ok.payload.to_bytes(), ResultAck).verdicts == ((a.trial_id, Verdict.INVALID),)
        assert storage.columns()["status"][a.trial_id] == b"waiting"
    finally:
        s.close()
        service.close()


def _result_for(a, coordinator: str) -> SubmittedResult:
    r = TrialResult(TrialStatus.COMPLETE, "", 1.0, 0, 0, 0, 0, 1, 0, 1, a.seed, trial_id=a.trial_id)
    return SubmittedResult(a.lease_id, r, coordinator=coordinator)


def _submit(session: zenoh.Session, run_id: str, item: SubmittedResult) -> ResultAck:
    sub = ResultSubmission("w", (item,))
    [reply] = list(session.get(keys.results(run_id), payload=encode_message(sub), timeout=5))
    return decode_message(reply.ok.payload.to_bytes(), ResultAck)


def test_each_open_of_a_run_is_a_new_stored_instance_and_results_leased_by_another_are_refused(tmp_path, caplog):
    from spinefarm.coordinator.setup import resume_run

    ep, out = free_endpoint(), tmp_path / "run.h5"
    core, storage, _ = sphere_core(trials=20, lease_s=3600, clock=time.monotonic, out=out)
    service = CoordinatorService(core, storage, listen=[ep]).start()
    s = zenoh.open(zenoh_config("client", connect=[ep]))
    try:
        first = _ask(s, core.run_id, WorkRequest("w", 2, code_digest=code_digest()))
        a, b = first.assignments
        service.close()   # the run stops with both trials leased by the first instance
        core, storage = resume_run(out, time.monotonic)
        service = CoordinatorService(core, storage, listen=[ep]).start()
        # the client's session reconnects to the new listener on its own: wait until it is answered
        wait_for(lambda: [r for r in s.get(keys.run_info(core.run_id), timeout=1) if r.ok is not None], poll_s=0.2,
                 what="the client's session back with the resumed coordinator")
        history = Hdf5Storage.open_read(out).run_meta().instances
        assert [h["how"] for h in history] == ["create", "resume"] and history[0]["instance"] != history[1]["instance"]
        assert first.coordinator == history[0]["instance"] and core.holder == history[1]["instance"]
        # the first instance's lease, resent to the second: refused with one log line, nothing stored
        with caplog.at_level("WARNING", logger="spinefarm.coordinator"):
            ack = _submit(s, core.run_id, _result_for(a, first.coordinator))
        assert ack.verdicts == ((a.trial_id, Verdict.STALE),) and ack.coordinator == core.holder
        said = [r.getMessage() for r in caplog.records if "leased by run instance" in r.getMessage()]
        assert len(said) == 1 and first.coordinator in said[0] and core.holder in said[0]
        assert storage.columns()["status"][a.trial_id] == b"waiting" and core.status()["foreign_results"] == 1
        assert core.forged_results == 0   # a lease of an earlier instance is not a forgery
        # the same lease naming the second instance (a forged label) is not this instance's lease: stale too
        assert _submit(s, core.run_id, _result_for(b, core.holder)).verdicts == ((b.trial_id, Verdict.STALE),)
        assert storage.columns()["status"][b.trial_id] == b"waiting"
        # a lease of this instance, returned naming it, is stored
        again = _ask(s, core.run_id, WorkRequest("w", 1, code_digest=code_digest()))
        [c] = again.assignments
        assert again.coordinator == core.holder
        assert _submit(s, core.run_id, _result_for(c, core.holder)).verdicts == ((c.trial_id, Verdict.STORED),)
        assert storage.columns()["status"][c.trial_id] == b"complete"
    finally:
        s.close()
        service.close()
