"""kill -9 of a coordinator with pending audits (a run of one worker: an audit needs another one), then
`--resume` with a second worker: every pending audit is issued again and run by the other worker (each one a
row of the evaluations table), and the run ends at exactly its budget. Real processes, Zenoh over TCP, a real
run file."""

from __future__ import annotations

import signal

import numpy as np
import pytest

from spinefarm.storage.hdf5 import Hdf5Storage
from spinefarm.storage.hdf5_reader import read_run
from tests.coordinator_tests.helpers import free_endpoint
from tests.coordinator_tests.procs import coordinator, stop, wait_status, worker

pytestmark = pytest.mark.integration


def test_pending_audits_are_issued_again_after_a_kill_and_the_run_ends_at_its_budget(tmp_path):
    ep, out = free_endpoint(), tmp_path / "run.h5"
    budget = 30
    coord = coordinator(ep, out, "sphere:4", "--trials", str(budget), "--duration", "0.04", "--run-id", "pa",
                        "--audit", "1")
    first = worker(ep, "pa", "w1")
    procs = [coord, first]
    try:
        wait_status(out, lambda st: st["trials_complete"] >= 8 and st["audit"].get("audits_pending", 0) >= 3,
                    "8 trials and 3 pending audits flushed")
        coord.send_signal(signal.SIGKILL)
        coord.wait(10)
        _, before = read_run(out)
        pending = np.flatnonzero(before["audit"] == b"pending")
        assert pending.size >= 3 and (before["worker_id"][pending] == b"w1").all()
        resumed = coordinator(ep, out, "--resume", str(out))
        second = worker(ep, "pa", "w2")
        procs += [resumed, second]
        assert resumed.wait(120) == 0
        for w in (first, second):
            assert w.wait(30) == 0
        with Hdf5Storage.open_read(out) as s:
            cols, ev = s.columns(), s.evaluations()
            assert cols["trial_id"].tolist() == list(range(budget))       # exactly its budget, no row twice
            assert set(cols["status"].tolist()) == {b"complete"}
            audited = {int(t): w for t, k, w in zip(ev["trial_id"], ev["kind"], ev["worker_id"], strict=True)
                       if k == b"audit"}
            rows = list(zip(ev["trial_id"].tolist(), ev["kind"].tolist(), ev["worker_id"].tolist(), strict=True))
            for tid in pending.tolist():   # each pending audit ran again, by the other worker, and agreed
                assert audited.get(tid) == b"w2" and cols["audit"][tid] == b"agrees", (tid, before["worker_id"][tid],
                                                                                       cols["worker_id"][tid], rows)
            assert not np.isin(cols["audit"], (b"pending", b"disputed")).any()
    finally:
        stop(*procs)
