"""Audits no single peer can satisfy, over real Zenoh: a forger using two worker ids in one Zenoh session cannot
audit itself, and a worker inflating every distance by 4.9 % (inside the 5 % tolerance) is caught, because
workers of the same code and environment must agree to the bit. Neither becomes the best; every row of a
quarantined session is marked and re-run by another identity."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import numpy as np
import zenoh

from spinefarm.coordinator.service import zenoh_config
from spinefarm.protocol import keys
from spinefarm.protocol.code_digest import code_digest
from spinefarm.protocol.envelope import decode_message, encode_message
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.states import TrialStatus
from spinefarm.protocol.submissions import SubmittedResult
from spinefarm.protocol.work import WorkGrant, WorkRequest
from spinefarm.storage.hdf5 import Hdf5Storage
from spinefarm.storage.status import read_status
from tests.coordinator_tests.helpers import free_endpoint, wait_for
from tests.coordinator_tests.procs import ROOT, coordinator, stop

FORGED_M = 123.4   # sphere:3 moves at most 3 m (its distance is 3 - |x - 0.3|^2)


def _worker(endpoint: str, run_id: str, worker_id: str, env: dict | None = None) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "spinefarm", "worker", "--connect", endpoint, "--run", run_id,
                             "--worker-id", worker_id, "--batch", "1", "--exit-when-done"], cwd=ROOT,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env={**os.environ, **(env or {})})


def _forged(a, worker_id: str, coordinator: str) -> SubmittedResult:
    r = TrialResult(TrialStatus.COMPLETE, "", FORGED_M, 100 * FORGED_M, 10 * FORGED_M, 1.0, 0.001, 10.0, 0.01, 1.0,
                    a.seed, trial_id=a.trial_id, worker_id=worker_id)
    return SubmittedResult(a.lease_id, r, coordinator=coordinator)


def _forge(endpoint: str, run_id: str, coord: subprocess.Popen, ids: tuple[str, ...], timeout_s: float) -> None:
    """One Zenoh session serving the run under several worker ids: every result and every audit it runs says
    FORGED_M, so its ids agree with each other. It asks until the coordinator exits (it hears "done")."""
    s = wait_for(lambda: _open(endpoint), timeout_s=30, poll_s=0.2, what="the coordinator listening")
    held = [s.liveliness().declare_token(keys.worker_token(w)) for w in ids]
    held += [s.declare_queryable(keys.worker_identity(w), lambda q: (q.reply(q.key_expr, b""), q.drop()))
             for w in ids]
    pending: dict[str, tuple] = {w: () for w in ids}
    end = time.monotonic() + timeout_s
    try:
        while coord.poll() is None and time.monotonic() < end:
            for w in ids:
                req = WorkRequest(w, 2, pending[w], code_digest=code_digest())
                replies = list(s.get(keys.work(run_id), payload=encode_message(req), timeout=5))
                grants = [decode_message(r.ok.payload.to_bytes(), WorkGrant) for r in replies if r.ok is not None]
                if grants:
                    pending[w] = tuple(_forged(a, w, grants[0].coordinator) for a in grants[0].assignments)
            time.sleep(0.02)
    finally:
        for h in held:
            h.undeclare()
        s.close()


def _open(endpoint: str) -> zenoh.Session | None:
    try:
        return zenoh.open(zenoh_config("client", connect=[endpoint]))
    except zenoh.ZError:
        return None


def _check_quarantined_rows(out, bad: set[bytes]) -> None:
    with Hdf5Storage.open_read(out) as s:
        cols = s.columns()
        bests = s.best(1)
    theirs = np.isin(cols["worker_id"], list(bad)) & (cols["status"] == b"complete")
    assert theirs.any()
    honest = (cols["status"] == b"complete") & ~theirs
    # on a busy machine the forger may take every trial: then no row may be best at all (each is disputed)
    assert len(bests) == int(honest.any())
    assert all(b.worker_id.encode() not in bad and b.distance_m <= 3.0 for b in bests)
    # every complete row of the quarantined session is marked and was re-run by another identity, which
    # measured what the result's parameters give
    assert set(cols["audit"][theirs].tolist()) == {b"disagrees"}
    assert not set(cols["audit_worker_id"][theirs].tolist()) & bad
    assert np.all(cols["audit_distance_m"][theirs] <= 3.0)
    status = read_status(out)
    assert {w["worker_id"] for w in status["workers"] if w["quarantined"]} == {b.decode() for b in bad}


def test_a_forger_with_two_worker_ids_in_one_session_cannot_audit_itself(tmp_path):
    ep, out = free_endpoint(), tmp_path / "run.h5"
    coord = coordinator(ep, out, "sphere:3", "--trials", "40", "--audit", "1", "--duration", "0.02",
                        "--run-id", "forge")
    honest = [_worker(ep, "forge", f"honest{i}") for i in range(2)]
    try:
        _forge(ep, "forge", coord, ("f1", "f2"), timeout_s=150)
        assert coord.wait(30) == 0
        _check_quarantined_rows(out, {b"f1", b"f2"})
        status = read_status(out)
        sessions = {w["worker_id"]: w["session"] for w in status["workers"]}
        assert sessions["f1"] == sessions["f2"] != sessions["honest0"]  # one identity, told apart by Zenoh
    finally:
        stop(coord, *honest)
    from spinefarm.api.app import create_app
    from tests.http_server import served

    with served(create_app(runs_dir=tmp_path)) as client:
        run = client.get("/runs/forge").json()
    assert {w["worker_id"]: w["session"] for w in run["workers"]} == sessions
    assert run["audit"]["comparisons"]["exact"] > 0 and run["claimed_by"] == {}


def test_a_worker_inflating_its_distances_by_4_9_percent_is_caught_by_exact_audits(tmp_path):
    ep, out = free_endpoint(), tmp_path / "run.h5"
    coord = coordinator(ep, out, "sphere:3", "--trials", "40", "--audit", "0.5", "--duration", "0.02",
                        "--run-id", "inflate")
    workers = [_worker(ep, "inflate", f"honest{i}") for i in range(2)]
    workers.append(_worker(ep, "inflate", "inflator", env={"SPINEFARM_FAULT_DISTANCE_SCALE": "1.049"}))
    try:
        assert coord.wait(150) == 0
        _check_quarantined_rows(out, {b"inflator"})
        comparisons = read_status(out)["audit"]["comparisons"]
        assert comparisons["exact"] > 0 and comparisons["tolerance"] == 0  # one machine: one environment
    finally:
        stop(coord, *workers)
