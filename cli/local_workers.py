"""Worker processes that `spinefarm search` starts on this machine, and keeps only as long as it lives.

Each worker runs `python -P -m spinefarm worker ...`: -P keeps the current directory off sys.path, so a
user's own `cli/` or `worker/` package cannot shadow ours. On Linux each worker asks the kernel for
SIGTERM when the search process dies (PR_SET_PDEATHSIG), so even a SIGKILLed search leaves no worker
behind. A worker that exits with an error is restarted a few times at most; then the search stops and
shows what the worker said.
"""

from __future__ import annotations

import contextlib
import ctypes
import signal
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path

PR_SET_PDEATHSIG = 1
MAX_FAILURES = 3
EXIT_UNSERVABLE = 3  # worker.service: the run cannot be built on this worker


def _die_with_parent() -> None:  # runs in the child between fork and exec
    with contextlib.suppress(OSError, AttributeError):  # elsewhere the search's own cleanup stops them
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)


def worker_command(endpoint: str, run_id: str, batch: int | None, zenoh_config: str | None,
                   credentials: str | None = None) -> list[str]:
    cmd = [sys.executable, "-P", "-m", "spinefarm", "worker", "--connect", endpoint, "--run", run_id,
           "--exit-when-done"]
    if batch:
        cmd += ["--batch", str(batch)]
    if zenoh_config:
        cmd += ["--zenoh-config", zenoh_config]
    if credentials:
        cmd += ["--credentials", credentials]
    return cmd


class LocalWorkers:
    """n worker processes; `check()` restarts those that died and says when to give up."""

    def __init__(self, command: Sequence[str], n: int, max_failures: int = MAX_FAILURES) -> None:
        self.command = list(command)
        self.max_failures = max_failures
        self.failures = 0
        self._logs = tempfile.TemporaryDirectory(prefix="spinefarm-workers-")
        self._spawned = 0
        self.procs: list[tuple[subprocess.Popen, Path]] = [self._spawn() for _ in range(n)]

    def _spawn(self) -> tuple[subprocess.Popen, Path]:
        self._spawned += 1
        log_path = Path(self._logs.name) / f"worker-{self._spawned}.log"
        with open(log_path, "wb") as err:
            proc = subprocess.Popen(self.command, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=err,
                                    preexec_fn=_die_with_parent if sys.platform.startswith("linux") else None)
        return proc, log_path

    @staticmethod
    def _tail(path: Path, lines: int = 6) -> str:
        try:
            text = path.read_text(errors="replace").strip().splitlines()
        except OSError:
            return ""
        return "\n".join(text[-lines:])

    def check(self) -> str | None:
        """Restart workers that exited early; a reason to stop the search once they keep failing."""
        for i, (proc, log_path) in enumerate(self.procs):
            code = proc.poll()
            if code is None:
                continue
            tail = self._tail(log_path)
            if code == EXIT_UNSERVABLE:
                return f"a local worker cannot serve this run:\n{tail}"
            self.failures += 1
            if self.failures >= self.max_failures:
                return (f"local workers keep failing ({self.failures} exits, last with code {code}); "
                        f"the last one said:\n{tail or '(nothing)'}")
            self.procs[i] = self._spawn()
        return None

    def stop(self, timeout_s: float = 10.0) -> None:
        import time

        for proc, _ in self.procs:
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        end = time.monotonic() + timeout_s
        for proc, _ in self.procs:
            try:
                proc.wait(max(0.1, end - time.monotonic()))
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        with contextlib.suppress(OSError):
            self._logs.cleanup()
