"""The progress line on a terminal: a bar that worker output and engine banners never break, and the
dashboard's real URL above it when port 8000 is taken."""

from __future__ import annotations

import os
import pty
import select
import socket
import subprocess
import sys
import time

import pytest

from tests.coordinator_tests.procs import ROOT

pytestmark = pytest.mark.integration


def run_on_a_terminal(args: list[str], timeout_s: float = 240.0) -> tuple[int, str]:
    leader, follower = pty.openpty()
    p = subprocess.Popen([sys.executable, "-m", "spinefarm", *args], cwd=ROOT, stdin=subprocess.DEVNULL,
                         stdout=follower, stderr=follower, env={**os.environ, "COLUMNS": "160"})
    os.close(follower)
    out = b""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        ready, _, _ = select.select([leader], [], [], 0.5)
        if ready:
            try:
                chunk = os.read(leader, 65536)
            except OSError:  # the terminal closed: the process is gone
                break
            if not chunk:
                break
            out += chunk
        elif p.poll() is not None:
            break
    os.close(leader)
    return p.wait(30), out.decode("utf-8", "replace")


def test_a_physics_search_on_a_terminal_keeps_its_progress_line_clean(tmp_path):
    with socket.socket() as busy:  # someone else holds port 8000's stand-in
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        taken = busy.getsockname()[1]
        code, out = run_on_a_terminal(["search", "tetraspine", "--trials", "2", "--workers", "1", "--duration",
                                       "0.5", "--out", str(tmp_path / "r.h5"), "--api-port", str(taken),
                                       "--engine", "bullet"])
    assert code == 0, out
    assert "pybullet build time" not in out  # neither the workers' nor the re-simulation's banner
    assert "Traceback" not in out
    assert f"(port {taken} is taken)" in out
    url_line = next(ln for ln in out.splitlines() if "dashboard on http://127.0.0.1:" in ln)
    assert f":{taken}/" not in url_line
    assert "2/2 parameter sets" in out and "\r" in out  # the bar redraws in place
    assert "best trial" in out
