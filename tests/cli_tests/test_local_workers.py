"""`search` keeps its local pool at strength: deaths are restarted (budgeted per window), only workers that
cannot start at all stop it."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from spinefarm.cli.local_workers import LocalWorkers
from spinefarm.storage.hdf5_reader import read_run
from tests.coordinator_tests.helpers import wait_for
from tests.coordinator_tests.procs import ROOT


def worker_children(pid: int) -> list[int]:
    out = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
            cmd = (d / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if int(stat.rsplit(")", 1)[1].split()[1]) == pid and b"worker" in cmd:
            out.append(int(d.name))
    return out


def test_search_survives_repeated_worker_kills(tmp_path):
    out = tmp_path / "r.h5"
    proc = subprocess.Popen([sys.executable, "-m", "spinefarm", "search", "sphere", "--trials", "80", "--workers",
                             "2", "--duration", "0.5", "--out", str(out), "--api-port", "-1", "--quiet"],
                            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        killed: set[int] = set()
        for _ in range(4):
            pid = wait_for(lambda: next((p for p in worker_children(proc.pid) if p not in killed), None),
                           timeout_s=30, what="a live worker")
            time.sleep(1.5)  # let it start and take a trial
            os.kill(pid, signal.SIGKILL)
            killed.add(pid)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    _, cols = read_run(out)
    assert len(cols["trial_id"]) == 80 and set(cols["status"].tolist()) <= {b"complete", b"failed"}


def test_workers_that_cannot_start_stop_the_search_and_deaths_after_a_start_do_not():
    never = LocalWorkers([sys.executable, "-c", "import sys; print('no luck', file=sys.stderr); sys.exit(1)"], 2)
    try:
        reason = wait_for(never.check, timeout_s=20, poll_s=0.05, what="the pool to give up")
        assert "cannot start" in reason and "no luck" in reason
    finally:
        never.stop()
    die = ("import os, sys, time; open(os.environ['SPINEFARM_READY_FILE'], 'w').close(); time.sleep(0.1); "
           "sys.exit(1)")
    crashy = LocalWorkers([sys.executable, "-c", die], 2, death_budget=3, death_window_s=30.0)
    try:
        end = time.monotonic() + 6.0
        while time.monotonic() < end:
            assert crashy.check() is None
            time.sleep(0.05)
        assert crashy.restarts == 6  # budget 3 per slot and window: the rest wait for room, nothing stops
        assert all(slot.proc is None for slot in crashy.slots)  # both wait for room in the window
    finally:
        crashy.stop()
