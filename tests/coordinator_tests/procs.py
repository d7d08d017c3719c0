"""Real `spinefarm` processes for the end-to-end and fault tests."""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

from spinefarm.storage.status import read_status
from tests.coordinator_tests.helpers import wait_for

ROOT = Path(__file__).resolve().parents[2]
# processes started and not yet seen to exit, with the files their standard error goes to: tests/conftest.py
# shows their last lines when a test fails
STARTED: list[tuple[list[str], Path, subprocess.Popen]] = []


def spinefarm(*args: str, quiet: bool = True) -> subprocess.Popen:
    if not quiet:
        return subprocess.Popen([sys.executable, "-m", "spinefarm", *args], cwd=ROOT, text=True)
    with tempfile.NamedTemporaryFile("w", prefix="spinefarm-", suffix=".log", delete=False) as log:
        proc = subprocess.Popen([sys.executable, "-m", "spinefarm", *args], cwd=ROOT, stdout=subprocess.PIPE,
                                stderr=log, text=True)
    STARTED.append((list(args), Path(log.name), proc))
    return proc


def log_tail(path: Path, lines: int) -> str:
    """The last lines of a process's log file."""
    return "\n".join(path.read_text(errors="replace").splitlines()[-lines:])


def forget_exited() -> None:
    """Drop the logs of processes that have exited (after each test)."""
    for entry in list(STARTED):
        if entry[2].poll() is not None:
            entry[1].unlink(missing_ok=True)
            STARTED.remove(entry)


def coordinator(endpoint: str, out: Path, *extra: str) -> subprocess.Popen:
    return spinefarm("coordinator", *extra, "--out" if "--resume" not in extra else "--quiet", *(
        [str(out)] if "--resume" not in extra else []), "--listen", endpoint, "--api-port", "-1", "--quiet")


def worker(endpoint: str, run_id: str, worker_id: str, batch: int = 1) -> subprocess.Popen:
    return spinefarm("worker", "--connect", endpoint, "--run", run_id, "--worker-id", worker_id,
                     "--batch", str(batch), "--exit-when-done")


def status(path: Path) -> dict:
    return read_status(path) or {}


def wait_status(path: Path, predicate, what: str, timeout_s: float = 60.0) -> dict:
    return wait_for(lambda: (st := status(path)) and predicate(st) and st, timeout_s=timeout_s, poll_s=0.05,
                    what=what)


def stop(*procs: subprocess.Popen) -> None:
    for p in procs:
        if p.poll() is None:
            p.kill()
        p.wait(10)
