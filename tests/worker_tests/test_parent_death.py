"""A helper process gets the signal it asked for when the process that started it is SIGKILLed (the kernel's
PR_SET_PDEATHSIG, worker/service/parent_death.py): the CLI's helpers SIGTERM, any other signal when asked."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

# the helper writes the number of the signal it got, then exits; it says it is ready once its handler is set
_HELPER = """
import os, signal, sys, time
from spinefarm.worker.service.parent_death import die_with_parent
signum, out = int(sys.argv[1]), sys.argv[2]
if {ask_itself}:
    die_with_parent(signum)
def got(n, _frame):
    with open(out + ".part", "w") as fh:
        fh.write(str(n))
    os.rename(out + ".part", out)  # whole when it appears
    os._exit(0)
signal.signal(signum, got)
print(os.getpid(), flush=True)
time.sleep(600)
"""

# the parent starts the helper (with the CLI's preexec_fn, or none: the helper asks itself), then sleeps
_PARENT = """
import subprocess, sys, time
from spinefarm.worker.service.parent_death import HELPER_PREEXEC
helper, signum, out, preexec = sys.argv[1:5]
subprocess.Popen([sys.executable, "-c", helper, signum, out],
                 preexec_fn=HELPER_PREEXEC if preexec == "yes" else None)
time.sleep(600)
"""


@pytest.mark.parametrize(("signum", "preexec"), [(signal.SIGTERM, "yes"), (signal.SIGUSR1, "no")],
                         ids=["cli-helper-sigterm", "asked-sigusr1"])
def test_a_helper_gets_its_signal_when_its_starter_is_killed(tmp_path, signum, preexec):
    out = tmp_path / "signal.txt"
    helper = _HELPER.format(ask_itself=preexec == "no")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    parent = subprocess.Popen([sys.executable, "-c", _PARENT, helper, str(int(signum)), str(out), preexec],
                              stdout=subprocess.PIPE, text=True, env=env)
    helper_pid = None
    try:
        helper_pid = int(parent.stdout.readline())  # the helper inherits the parent's stdout
        parent.kill()
        parent.wait(10)
        deadline = time.monotonic() + 10.0
        while not out.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert out.exists(), "the helper outlived the process that started it"
        assert out.read_text() == str(int(signum))
    finally:
        parent.kill()
        if helper_pid is not None and not out.exists():
            os.kill(helper_pid, signal.SIGKILL)
