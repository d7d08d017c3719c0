"""SIGINT or SIGTERM during a calibration (a search's, or `spinefarm calibrate`'s) or an accuracy sweep ends
every process the command started within 5 s: from a script (the signal reaches the command alone) and from a
terminal's Ctrl-C (it reaches the whole process group). Real processes; every one the command starts carries
a marker in its environment, found through /proc."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

from tests.coordinator_tests.procs import ROOT

pytestmark = pytest.mark.integration

MARK = "SPINEFARM_TEST_MARK"
GONE_WITHIN_S = 5.0


def marked(token: str) -> set[int]:
    """Every live process whose environment carries MARK=token."""
    needle = f"{MARK}={token}".encode()
    found = set()
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            if needle in (entry / "environ").read_bytes().split(b"\0"):
                state = (entry / "stat").read_text().rsplit(")", 1)[1].split()[0]
                if state != "Z":  # a zombie has ended; only its parent has not read its status yet
                    found.add(int(entry.name))
        except OSError:
            continue
    return found


def wait_until(test, timeout_s: float, every_s: float = 0.1) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if test():
            return True
        time.sleep(every_s)
    return test()


def _as_from_a_terminal() -> None:
    """SIGINT as a terminal or a script gives it: a suite started in the background of a non-interactive shell
    (`make test &`) inherits SIGINT ignored (POSIX), and an ignored signal stays ignored across exec."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


COMMANDS = {
    "search": ["search", "tetraspine-ntrt", "--trials", "4", "--workers", "2", "--duration", "1", "--api-port", "-1",
               "--calibrate-gaits", "200", "--calibrate-duration", "3", "--quiet"],
    "calibrate": ["calibrate", "tetraspine-ntrt", "--gaits", "200", "--duration", "3"],
    "accuracy": ["accuracy", "tetraspine-ntrt", "--quick", "--seeds", "8"],
}


@pytest.mark.parametrize(("command", "how"), [("search", "script-sigint"), ("search", "terminal-ctrl-c"),
                                              ("search", "sigterm"), ("calibrate", "sigterm"),
                                              ("calibrate", "terminal-ctrl-c"), ("accuracy", "script-sigint")])
def test_a_stop_signal_during_a_pool_leaves_no_process(tmp_path, command, how):
    token = uuid.uuid4().hex
    env = {**os.environ, MARK: token, "SPINEFARM_CACHE_DIR": str(tmp_path / "cache"), "PYTHONPATH": str(ROOT)}
    args = [*COMMANDS[command], *(["--out", str(tmp_path / "run.h5")] if command == "search" else []),
            *(["--out", str(tmp_path / "acc")] if command == "accuracy" else [])]
    log = (tmp_path / "stderr.log").open("w")
    proc = subprocess.Popen([sys.executable, "-m", "spinefarm", *args], cwd=tmp_path, env=env,
                            stdout=subprocess.DEVNULL, stderr=log, start_new_session=True,
                            preexec_fn=_as_from_a_terminal)
    try:
        # the command, (a search's calibration child,) and a pool of 2 at work
        want = 4 if command == "search" else 3
        assert wait_until(lambda: len(marked(token)) >= want, 120.0), (tmp_path / "stderr.log").read_text()[-2000:]
        time.sleep(0.5)
        if how == "terminal-ctrl-c":
            os.killpg(proc.pid, signal.SIGINT)
        else:
            proc.send_signal(signal.SIGTERM if how == "sigterm" else signal.SIGINT)
        start = time.monotonic()
        gone = wait_until(lambda: proc.poll() is not None and not marked(token), GONE_WITHIN_S)
        left = marked(token)
        assert gone, f"{len(left)} processes left {time.monotonic() - start:.1f} s after {how}: {sorted(left)}"
    finally:
        for pid in marked(token):
            os.kill(pid, signal.SIGKILL)
        proc.kill()
        proc.wait()
        log.close()
