"""Nothing runs or waits for ever: workers of a run that ended while they
were frozen, damaged files on resume, errors while starting up."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

from spinefarm.storage.hdf5_reader import read_run
from spinefarm.storage.probe import check_eof
from tests.coordinator_tests.helpers import free_endpoint
from tests.coordinator_tests.procs import ROOT, coordinator, spinefarm, stop, wait_status
from tests.coordinator_tests.test_run_file_faults import finished_run

TRIALS = 150  # of 0.05 s: the two frozen workers cannot run them all before they are frozen


def test_a_worker_frozen_until_its_run_ended_exits_after_waking(tmp_path):
    # Two workers frozen until the run is done (their tokens gone: not live). One wakes as the run ends:
    # the coordinator waits for it, so it hears "done" instead of waiting out its 60 s --coordinator-timeout.
    # The other wakes only after the coordinator has left: nobody is there to tell it, its 3 s timeout ends it.
    ep, out = free_endpoint(), tmp_path / "run.h5"
    coord = coordinator(ep, out, "sphere:4", "--trials", str(TRIALS), "--duration", "0.05", "--run-id", "ended")
    woken, late = (spinefarm("worker", "--connect", ep, "--run", "ended", "--worker-id", name, "--exit-when-done",
                             "--coordinator-timeout", timeout_s)
                   for name, timeout_s in (("woken", "60"), ("late", "3")))
    other = None
    try:
        wait_status(out, lambda st: {"woken", "late"} <= {w["worker_id"] for w in st["workers"]}, "workers to join")
        woken.send_signal(signal.SIGSTOP)
        late.send_signal(signal.SIGSTOP)
        # the rest of the run (seconds of trials) outlasts their 2 s transport lease
        other = spinefarm("worker", "--connect", ep, "--run", "ended", "--worker-id", "other", "--exit-when-done")
        st = wait_status(out, lambda st: st["state"] == "done", "the run to end without them")
        assert not any(w["alive"] for w in st["workers"] if w["worker_id"] in ("woken", "late")), st["workers"]
        woken.send_signal(signal.SIGCONT)
        assert woken.wait(30) == 0  # well inside its 60 s coordinator timeout: it was told
        assert coord.wait(60) == 0 and other.wait(30) == 0
        late.send_signal(signal.SIGCONT)
        t0 = time.monotonic()
        assert late.wait(30) == 0
        assert time.monotonic() - t0 < 20
    finally:
        for p in (woken, late):
            if p.poll() is None:
                p.send_signal(signal.SIGCONT)
        stop(coord, woken, late, *([other] if other else []))
    _, cols = read_run(out)
    assert int((cols["status"] == b"complete").sum()) == TRIALS


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
