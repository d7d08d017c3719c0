"""A local pool's log folder carries its search's PID (spinefarm-workers-PID-XXXX in the temp folder); a new pool
removes the folders of searches whose process is gone, so searches killed outright do not pile them up."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

from spinefarm.cli.local_workers import LocalWorkers
from tests.coordinator_tests.helpers import wait_for
from tests.coordinator_tests.procs import ROOT

QUIET = [sys.executable, "-c", "import time; time.sleep(30)"]


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid  # reaped: no process has this PID until the kernel hands it out again


def test_a_new_pool_removes_the_logs_of_dead_searches_and_keeps_the_live_ones(tmp_path):
    sleeper = subprocess.Popen(QUIET)  # a search still running
    dead = tmp_path / f"spinefarm-workers-{_dead_pid()}-abc"
    live = tmp_path / f"spinefarm-workers-{sleeper.pid}-def"
    older = tmp_path / "spinefarm-workers-k3j_x9q1"             # no PID in the name: nothing says its search ended
    for folder in (dead, live, older):
        folder.mkdir()
        (folder / "worker-1.log").write_text("a worker's last words\n")
    pool = LocalWorkers(QUIET, 1, logs_root=tmp_path)
    try:
        assert not dead.exists()
        assert (live / "worker-1.log").exists() and (older / "worker-1.log").exists()
        own = sorted(tmp_path.glob(f"spinefarm-workers-{os.getpid()}-*"))
        assert len(own) == 1 and (own[0] / "worker-1.log").exists()
    finally:
        pool.stop()
        sleeper.kill()
        sleeper.wait()
    assert not own[0].exists()


def test_the_logs_of_a_search_killed_outright_are_removed_by_the_next_pool(tmp_path):
    env = dict(os.environ, TMPDIR=str(tmp_path))
    search = subprocess.Popen([sys.executable, "-m", "spinefarm", "search", "sphere", "--trials", "50", "--workers",
                               "1", "--duration", "0.5", "--out", str(tmp_path / "r.h5"), "--api-port", "-1",
                               "--quiet"], cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        left = wait_for(lambda: sorted(tmp_path.glob(f"spinefarm-workers-{search.pid}-*")), timeout_s=60,
                        poll_s=0.1, what="the search's log folder")
    finally:
        search.send_signal(signal.SIGKILL)
        search.wait(10)
    assert left[0].is_dir()  # SIGKILL: the search could not remove it
    pool = LocalWorkers(QUIET, 1, logs_root=tmp_path)
    pool.stop()
    assert not left[0].exists()
