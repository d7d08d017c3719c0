"""Nothing runs or waits for ever: workers of a run that ended while they
were frozen, damaged files on resume, errors while starting up."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

from spinefarm.storage.probe import check_eof

from tests.coordinator_tests.helpers import free_endpoint
from tests.coordinator_tests.procs import ROOT, coordinator, spinefarm, stop, wait_status
from tests.coordinator_tests.test_run_file_faults import finished_run


def test_a_worker_frozen_until_its_run_ended_exits_after_waking(tmp_path):
    ep, out = free_endpoint(), tmp_path / "run.h5"
    coord = coordinator(ep, out, "sphere:4", "--trials", "30", "--duration", "0.05", "--run-id", "ended")
    frozen = spinefarm("worker", "--connect", ep, "--run", "ended", "--worker-id", "frozen", "--exit-when-done",
                       "--coordinator-timeout", "3")
    other = spinefarm("worker", "--connect", ep, "--run", "ended", "--worker-id", "other", "--exit-when-done")
    try:
        wait_status(out, lambda st: any(w["worker_id"] == "frozen" for w in st["workers"]), "the worker to join")
        frozen.send_signal(signal.SIGSTOP)
        assert coord.wait(60) == 0 and other.wait(30) == 0  # the run ends without it
        frozen.send_signal(signal.SIGCONT)
        t0 = time.monotonic()
        assert frozen.wait(30) == 0
        assert time.monotonic() - t0 < 20
    finally:
        if frozen.poll() is None:
            frozen.send_signal(signal.SIGCONT)
        stop(coord, frozen, other)


def test_resuming_a_truncated_file_is_a_clear_error_within_seconds(tmp_path):
    path = tmp_path / "run.h5"
    finished_run(path)
    os.truncate(path, path.stat().st_size // 2)
    t0 = time.monotonic()
    r = subprocess.run([sys.executable, "-m", "spinefarm", "search", "--resume", str(path), "--workers", "0",
                        "--api-port", "-1"], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "is truncated" in r.stderr, r.stderr
    assert time.monotonic() - t0 < 10
    try:
        check_eof(path)
    except Exception as exc:
        assert "truncated" in str(exc)


def test_a_startup_error_ends_the_coordinator_with_the_error(tmp_path):
    r = subprocess.run([sys.executable, "-m", "spinefarm", "search", "sphere:3", "--trials", "20", "--workers", "1",
                        "--out", str(tmp_path / "run.h5"), "--api-host", "999.1.1.1"], cwd=ROOT, capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 2 and "cannot serve the API on 999.1.1.1" in r.stderr, r.stderr
    # The file was released: the run can be continued at once.
    r = subprocess.run([sys.executable, "-m", "spinefarm", "search", "--resume", str(tmp_path / "run.h5"), "--workers",
                        "1", "--api-port", "-1"], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
