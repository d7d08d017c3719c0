"""Run files made by real short searches, and one `spinefarm api` over them, shared by the dashboard view tests
of this session: a sphere run of two workers, a multi-fidelity run, a run of few trials maximising speed, a run
that never finished a trial, a damaged file, and a run of a robot from a spec file."""

from __future__ import annotations

import shutil
import signal
import subprocess
import sys

import pytest

from tests.api_tests.judged import OLD, write_cot_run
from tests.api_tests.test_dashboard_browser import ARTIFACTS, Server, chromium_path, free_port, spinefarm
from tests.coordinator_tests.helpers import wait_for
from tests.coordinator_tests.procs import ROOT

SPEC_ROBOT = "explore-spine"  # the name the spec file gives its robot


@pytest.fixture(scope="module")
def browser():
    """One headless Chromium per test module (Debian's, driven by Playwright)."""
    from playwright.sync_api import sync_playwright

    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=chromium_path(), args=["--no-sandbox"])
        yield b
        b.close()


@pytest.fixture(scope="session")
def views_runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("views")
    spinefarm("search", "sphere:9", "--trials", "60", "--workers", "2", "--duration", "0.05", "--out",
              str(d / "two.h5"), "--run-id", "two-workers", "--api-port", "-1", "--quiet", "--seed", "1")
    spinefarm("search", "sphere:3", "--rungs", "0.05,0.1", "--trials", "30", "--workers", "1", "--out",
              str(d / "rungs.h5"), "--run-id", "rungs-view", "--api-port", "-1", "--quiet", "--sampler", "random")
    spinefarm("search", "sphere:40", "--trials", "8", "--workers", "1", "--out", str(d / "few.h5"),
              "--run-id", "few-trials", "--api-port", "-1", "--quiet", "--objective", "speed")
    # a robot from a spec file (NTRT's three segments, renamed), a few short trials in the fast tier
    spec = tmp_path_factory.mktemp("robot") / f"{SPEC_ROBOT}.yaml"
    spec.write_text(spinefarm("spec", "tetraspine-ntrt", "--name", SPEC_ROBOT).stdout)
    spinefarm("search", str(spec), "--engine", "mujoco", "--trials", "6", "--workers", "1", "--duration", "0.2",
              "--out", str(d / "spec.h5"), "--run-id", "spec-robot", "--api-port", "-1", "--quiet")
    # a search with no workers, stopped: a run file without a finished trial
    proc = subprocess.Popen([sys.executable, "-m", "spinefarm", "search", "sphere:3", "--trials", "10", "--workers",
                             "0", "--out", str(d / "empty.h5"), "--run-id", "empty-run", "--api-port", "-1",
                             "--quiet"], cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    wait_for(lambda: (d / "empty.h5.status.json").exists(), timeout_s=60, poll_s=0.1, what="the run file")
    proc.send_signal(signal.SIGINT)
    proc.wait(60)
    (d / "broken.h5").write_bytes(b"not a run file at all\n" * 10)
    return d


@pytest.fixture(scope="session")
def views_server(views_runs):
    port = free_port()
    s = Server(["api", "--runs-dir", str(views_runs), "--port", str(port)], port)
    yield s
    s.stop()


@pytest.fixture(scope="session")
def judged_server(tmp_path_factory):
    """One `spinefarm api` over two judged run files, for the pages that only read them: run-c (judged, each row
    with its COT: tests.api_tests.judged) and run-v8 (a schema 8 file, no COT column)."""
    d = tmp_path_factory.mktemp("judged")
    write_cot_run(d / "c.h5")
    shutil.copy(OLD, d / "old.h5")
    port = free_port()
    s = Server(["api", "--runs-dir", str(d), "--port", str(port)], port)
    yield s
    s.stop()
