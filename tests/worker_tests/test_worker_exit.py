"""--exit-when-done stops a worker whatever it still holds, and a worker the router refuses says so."""

from __future__ import annotations

import os
import secrets
import signal
import subprocess
import sys
import time

from tests.coordinator_tests.helpers import free_endpoint
from tests.coordinator_tests.procs import ROOT, coordinator, stop, wait_status, worker


def spinefarm_err(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "spinefarm", *args], cwd=ROOT, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)


def test_a_roaming_worker_frozen_past_the_end_of_its_run_exits_holding_an_unacknowledged_result(tmp_path):
    ep, out = free_endpoint(), tmp_path / "run.h5"
    coord = coordinator(ep, out, "sphere:3", "--trials", "6", "--duration", "2", "--run-id", "frozen")
    roaming = spinefarm_err("worker", "--connect", ep, "--worker-id", "roaming", "--batch", "1",
                            "--exit-when-done", "--coordinator-timeout", "3")
    helper = None
    try:
        wait_status(out, lambda st: any(w["worker_id"] == "roaming" for w in st["workers"]), "the roaming worker")
        time.sleep(0.5)  # inside its 2 s trial
        os.kill(roaming.pid, signal.SIGSTOP)
        helper = worker(ep, "frozen", "helper")
        assert coord.wait(90) == 0 and helper.wait(30) == 0
        os.kill(roaming.pid, signal.SIGCONT)  # it finishes its trial: a result nobody will acknowledge
        t0 = time.monotonic()
        _, err = roaming.communicate(timeout=40)
        assert roaming.returncode == 0, err
        assert time.monotonic() - t0 < 3 + 25
    finally:
        if roaming.poll() is None:
            os.kill(roaming.pid, signal.SIGCONT)
        stop(coord, roaming, *([helper] if helper else []))


def test_a_refused_worker_says_so_and_exit_when_done_stops_it(tmp_path):
    creds = tmp_path / "all"
    creds.write_text(f"coordinator:{secrets.token_hex(16)}\nworker:{secrets.token_hex(16)}\n")
    wrong = tmp_path / "wrong"
    wrong.write_text(f"worker:{secrets.token_hex(16)}\n")
    for f in (creds, wrong):
        f.chmod(0o600)
    ep, out = free_endpoint(), tmp_path / "run.h5"
    coord = coordinator(ep, out, "sphere:3", "--trials", "40", "--run-id", "locked", "--credentials", str(creds))
    stays = exits = None
    try:
        wait_status(out, lambda st: st["state"] == "running", "the coordinator")
        exits = spinefarm_err("worker", "--connect", ep, "--run", "locked", "--credentials", str(wrong),
                              "--exit-when-done", "--coordinator-timeout", "4")
        stays = spinefarm_err("worker", "--connect", ep, "--run", "locked")
        _, err = exits.communicate(timeout=30)
        assert exits.returncode == 4 and "refused by" in err and "credentials" in err, err
        time.sleep(2.0)
        assert stays.poll() is None  # without --exit-when-done it keeps trying
        stays.send_signal(signal.SIGTERM)
        _, err2 = stays.communicate(timeout=20)
        assert "refused by" in err2, err2
    finally:
        stop(coord, *[p for p in (stays, exits) if p is not None])
