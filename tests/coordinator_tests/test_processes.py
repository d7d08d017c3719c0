"""End-to-end and fault tests with real processes, real Zenoh over TCP on loopback and real files."""

from __future__ import annotations

import signal

import httpx
import numpy as np
import pytest

from spinefarm.storage.hdf5 import Hdf5Storage
from spinefarm.storage.hdf5_reader import read_run
from tests.coordinator_tests.helpers import free_endpoint, wait_for
from tests.coordinator_tests.procs import coordinator, spinefarm, status, stop, wait_status, worker

pytestmark = pytest.mark.integration


def assert_every_trial_once(path, budget: int) -> Hdf5Storage:
    s = Hdf5Storage.open_read(path)
    cols = s.columns()
    assert cols["trial_id"].tolist() == list(range(budget))
    assert set(cols["status"].tolist()) == {b"complete"}, s.counts()
    assert np.isfinite(cols["distance_m"]).all()
    return s


def test_coordinator_two_workers_and_api_run_a_search(tmp_path):
    ep, out = free_endpoint(), tmp_path / "run.h5"
    coord = coordinator(ep, out, "sphere:4", "--trials", "60", "--duration", "0.02", "--run-id", "e2e",
                        "--batch", "1")
    workers = [worker(ep, "e2e", f"w{i}", batch=4) for i in range(2)]
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    wait_for(out.exists, timeout_s=30, poll_s=0.05, what="the run file")  # the API serves an existing file
    api = spinefarm("api", str(out), "--port", str(port))
    try:
        assert coord.wait(60) == 0
        for w in workers:
            assert w.wait(20) == 0
        s = assert_every_trial_once(out, 60)
        assert set(s.columns()["worker_id"].tolist()) == {b"w0", b"w1"}

        def api_state():
            try:
                return httpx.get(f"http://127.0.0.1:{port}/runs/e2e", timeout=2).json()
            except httpx.TransportError:
                return None
        st = wait_for(api_state, timeout_s=30, poll_s=0.1, what="the API")
        assert st["state"] == "done" and st["trials_done"] == 60 and st["best"] is not None
    finally:
        stop(coord, api, *workers)


def test_sigkilled_worker_trial_is_reissued_and_completed_once(tmp_path):
    ep, out = free_endpoint(), tmp_path / "run.h5"
    coord = coordinator(ep, out, "sphere:4", "--trials", "8", "--duration", "0.6", "--run-id", "kw")
    victim = worker(ep, "kw", "victim")
    survivor = worker(ep, "kw", "survivor")
    try:
        wait_status(out, lambda st: any(w["worker_id"] == "victim" and w["leases"] > 0 for w in st["workers"]),
                    "the victim to hold a trial")
        victim.send_signal(signal.SIGKILL)
        victim.wait(10)
        assert coord.wait(60) == 0
        assert survivor.wait(20) == 0
        final = status(out)
        assert final["trials_reissued"] >= 1 and final["state"] == "done"
        s = assert_every_trial_once(out, 8)
        assert b"survivor" in s.columns()["worker_id"].tolist()
    finally:
        stop(coord, victim, survivor)


def test_sigkilled_coordinator_resumes_and_completes_the_budget(tmp_path):
    ep, out = free_endpoint(), tmp_path / "run.h5"
    budget = 150
    coord = coordinator(ep, out, "sphere:4", "--trials", str(budget), "--duration", "0.04", "--run-id", "kc")
    workers = [worker(ep, "kc", f"w{i}", batch=2) for i in range(2)]
    resumed = None
    try:
        wait_status(out, lambda st: st["trials_complete"] >= 40, "40 trials flushed")
        coord.send_signal(signal.SIGKILL)
        coord.wait(10)
        _, before = read_run(out)  # the killed writer's file opens, with every flushed row
        done_before = np.flatnonzero(before["status"] == b"complete")
        assert done_before.size >= 40
        resumed = coordinator(ep, out, "--resume", str(out))
        assert resumed.wait(60) == 0
        for w in workers:
            assert w.wait(20) == 0
        s = assert_every_trial_once(out, budget)
        after = s.columns()
        for name in ("params_unit", "distance_m", "worker_id", "seed", "phase", "parent"):
            assert (after[name][done_before] == before[name][done_before]).all(), name
        assert s.run_meta().run_id == "kc"
    finally:
        stop(coord, *workers, *([resumed] if resumed else []))


def test_late_joiner_and_a_leaver(tmp_path):
    ep, out = free_endpoint(), tmp_path / "run.h5"
    coord = coordinator(ep, out, "sphere:4", "--trials", "40", "--duration", "0.1", "--run-id", "jl")
    early = worker(ep, "jl", "early")
    late = None
    try:
        wait_status(out, lambda st: st["trials_complete"] >= 3, "the early worker's first trials")
        late = worker(ep, "jl", "late")
        wait_for(lambda: b"late" in read_run(out)[1]["worker_id"].tolist(), timeout_s=30, poll_s=0.1,
                 what="the late worker's first stored result")
        early.send_signal(signal.SIGTERM)  # leaves cleanly: returns what it ran, then exits
        assert early.wait(20) == 0
        assert coord.wait(60) == 0
        assert late.wait(20) == 0
        s = assert_every_trial_once(out, 40)
        ids = s.columns()["worker_id"].tolist()
        assert ids.count(b"early") >= 3 and ids.count(b"late") >= 1
    finally:
        stop(coord, early, *([late] if late else []))


def test_physics_search_with_two_worker_processes(tmp_path):
    pytest.importorskip("spinefarm.worker.trial.simulation")
    out = tmp_path / "tetra.h5"
    proc = spinefarm("search", "tetraspine", "--trials", "4", "--workers", "2", "--duration", "0.5",
                     "--out", str(out), "--api-port", "-1", "--quiet", "--engine", "bullet")
    stdout, _ = proc.communicate(timeout=180)
    assert proc.returncode == 0
    assert "best trial" in stdout and str(out) in stdout
    s = assert_every_trial_once(out, 4)
    cols = s.columns()
    assert len(set(cols["worker_id"].tolist())) == 2
    assert (cols["sim_time_s"] == pytest.approx(0.5, abs=0.01))
    assert s.run_meta().morphology == "tetraspine" and s.run_meta().n_params == cols["params"].shape[1]


ROUTER = """
import json, sys, time, zenoh
conf = zenoh.Config()
conf.insert_json5("mode", '"router"')
conf.insert_json5("listen/endpoints", json.dumps([sys.argv[1]]))
conf.insert_json5("scouting/multicast/enabled", "false")
session = zenoh.open(conf)
print("up", flush=True)
time.sleep(3600)
"""


def test_two_runs_share_one_router_and_one_pool_of_workers(tmp_path):
    import subprocess
    import sys

    ep = free_endpoint()
    router = subprocess.Popen([sys.executable, "-c", ROUTER, ep], stdout=subprocess.PIPE, text=True)
    coords, workers = [], []
    try:
        assert router.stdout.readline().strip() == "up"
        for run_id, n in (("run-a", 40), ("run-b", 30)):
            coords.append(spinefarm("coordinator", "sphere:3", "--trials", str(n), "--run-id", run_id, "--out",
                                    str(tmp_path / f"{run_id}.h5"), "--connect", ep, "--api-port", "-1", "--quiet"))
        # Workers are not told a run: they discover both through the router and serve them in turn.
        workers = [spinefarm("worker", "--connect", ep, "--worker-id", f"r{i}", "--exit-when-done")
                   for i in range(2)]
        for c in coords:
            assert c.wait(60) == 0
        for w in workers:
            assert w.wait(20) == 0
        assert_every_trial_once(tmp_path / "run-a.h5", 40)
        assert_every_trial_once(tmp_path / "run-b.h5", 30)
    finally:
        stop(router, *coords, *workers)


def test_frozen_worker_is_dropped_and_its_late_result_is_not_stored(tmp_path):
    ep, out = free_endpoint(), tmp_path / "run.h5"
    coord = coordinator(ep, out, "sphere:4", "--trials", "12", "--duration", "0.5", "--run-id", "fz")
    frozen = worker(ep, "fz", "frozen")
    other = worker(ep, "fz", "other")
    try:
        wait_status(out, lambda st: any(w["worker_id"] == "frozen" and w["leases"] > 0 for w in st["workers"]),
                    "the frozen worker to hold a trial")
        frozen.send_signal(signal.SIGSTOP)
        # Its token survives until its 2 s transport lease expires; then its trial is re-issued.
        wait_status(out, lambda st: any(w["worker_id"] == "frozen" and not w["alive"] for w in st["workers"]),
                    "the coordinator to drop the frozen worker")
        frozen.send_signal(signal.SIGCONT)  # wakes, finishes its trial and returns it: stale
        assert coord.wait(60) == 0
        final = status(out)
        assert final["trials_reissued"] >= 1
        # Dropped as stale, or as a duplicate when the re-issued copy was stored first: never twice.
        assert final["dropped_results"]["stale"] + final["dropped_results"]["duplicate"] >= 1, final
        assert_every_trial_once(out, 12)
    finally:
        for p in (frozen,):
            if p.poll() is None:
                p.send_signal(signal.SIGCONT)
        stop(coord, frozen, other)


def test_ctrl_c_stops_a_local_search_with_everything_stored_and_resume_extends_it(tmp_path):
    import os
    import subprocess
    import sys

    from tests.coordinator_tests.procs import ROOT

    out = tmp_path / "run.h5"
    cmd = [sys.executable, "-m", "spinefarm", "search", "sphere:4", "--trials", "120", "--workers", "2",
           "--duration", "0.05", "--out", str(out), "--api-port", "-1", "--quiet"]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        seen = wait_status(out, lambda st: st["trials_complete"] >= 20, "20 trials")["trials_complete"]
        os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in a terminal does: the whole group
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        stop(proc)
    assert proc.returncode == 130
    assert f"spinefarm search --resume {out}" in stderr and "best trial" in stdout
    s = Hdf5Storage.open_read(out)
    assert seen <= s.counts()["complete"] < 120
    assert status(out)["state"] == "stopped"
    # Resume to a larger budget: numbering continues, the run completes to the new budget.
    resumed = spinefarm("search", "--resume", str(out), "--trials", "150", "--workers", "2", "--api-port", "-1",
                        "--quiet")
    assert resumed.wait(60) == 0
    assert_every_trial_once(out, 150)


@pytest.mark.slow
def test_repeated_sigkills_of_the_coordinator_at_random_moments(tmp_path):
    """kill -9 at any moment: every time the file opens with its flushed rows and the run resumes."""
    import random
    import time

    ep, out = free_endpoint(), tmp_path / "run.h5"
    budget = 3000
    rng = random.Random(4)
    coord = coordinator(ep, out, "sphere:6", "--trials", str(budget), "--duration", "0.002", "--run-id", "rk")
    workers = [worker(ep, "rk", f"w{i}") for i in range(2)]
    kept = {}
    try:
        for _ in range(6):
            wait_for(lambda: out.exists() and status(out).get("trials_complete", 0) > len(kept), timeout_s=60,
                     poll_s=0.05, what="progress since the last resume")
            time.sleep(rng.uniform(0.0, 1.5))  # a random moment, not a deadline
            if coord.poll() is not None:
                break
            coord.send_signal(signal.SIGKILL)
            coord.wait(10)
            _, cols = read_run(out)
            done = np.flatnonzero(cols["status"] == b"complete")
            for i in np.flatnonzero(cols["status"] != b"waiting"):
                if int(i) in kept:  # a finished trial never changes across kills
                    assert kept[int(i)] == float(cols["distance_m"][i])
            kept.update({int(i): float(cols["distance_m"][i]) for i in done})
            coord = coordinator(ep, out, "--resume", str(out))
        assert coord.wait(120) == 0
        s = assert_every_trial_once(out, budget)
        dist = s.columns()["distance_m"]
        assert all(dist[i] == d for i, d in kept.items())
    finally:
        stop(coord, *workers)
