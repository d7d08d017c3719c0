"""Worker processes that `spinefarm search` starts on this machine, and keeps only as long as it lives.

Each worker runs `python -P -m spinefarm worker ...`: -P keeps the current directory off sys.path, so a
user's own `cli/` or `worker/` package cannot shadow ours. On Linux each worker asks the kernel for
SIGTERM when the search process dies (PR_SET_PDEATHSIG), so even a SIGKILLed search leaves no worker
behind.

The pool is kept at strength. A worker that started (it wrote its ready file, READY_ENV, once its
session was open) and then died is restarted: a trial that keeps killing its workers is the scheduler's
business (it is stored as failed after 3 lost leases), not a reason to stop the search. Deaths are
budgeted per time window: beyond DEATH_BUDGET in DEATH_WINDOW_S a restart waits until the window has
room, so a crash loop costs little CPU. Only workers that cannot start at all stop the search: MAX_FAILURES
start failures in a row (exits before the ready file) with no start in between.

The workers' logs and ready files live in the temp folder, in spinefarm-workers-PID-XXXX (PID: the search's);
the search removes it when it stops. A search killed outright (SIGKILL) cannot, so each new pool first removes
the folders of searches whose process is gone.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections import deque
from collections.abc import Sequence
from pathlib import Path

from spinefarm.worker.service.parent_death import HELPER_PREEXEC

MAX_FAILURES = 3            # start failures in a row before the search stops
DEATH_WINDOW_S = 60.0
DEATH_BUDGET = 10           # restarts after deaths per window and worker slot; more wait for room
EXIT_UNSERVABLE = 3  # worker.service.zenoh_worker: the run cannot be built on this worker
READY_ENV = "SPINEFARM_READY_FILE"   # worker.service.zenoh_worker writes this file once it has started
LOGS_PREFIX = "spinefarm-workers-"  # + the search's PID + "-" + a random tail


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


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # another user's process
    return True


def remove_orphaned_logs(root: Path) -> list[Path]:
    """Remove the log folders under `root` of searches whose process is gone; the ones removed. A folder
    without a PID in its name (older versions) is left alone: nothing says whether its search still runs."""
    removed = []
    for folder in root.glob(f"{LOGS_PREFIX}*-*"):
        pid = folder.name[len(LOGS_PREFIX):].split("-", 1)[0]
        if folder.is_dir() and pid.isdigit() and not _process_alive(int(pid)):
            shutil.rmtree(folder, ignore_errors=True)
            removed.append(folder)
    return removed


class _Slot:
    """One worker process of the pool and where it writes its log and its ready file."""

    def __init__(self, proc: subprocess.Popen | None, log_path: Path, ready_path: Path) -> None:
        self.proc, self.log_path, self.ready_path = proc, log_path, ready_path


class LocalWorkers:
    """n worker processes; `check()` restarts those that died and says when to give up."""

    def __init__(self, command: Sequence[str], n: int, max_failures: int = MAX_FAILURES,
                 death_budget: int = DEATH_BUDGET, death_window_s: float = DEATH_WINDOW_S,
                 logs_root: Path | None = None) -> None:
        self.command = list(command)
        self.max_failures = max_failures
        self.death_budget = death_budget * max(n, 1)
        self.death_window_s = death_window_s
        self.start_failures = 0          # in a row, since the last worker that started
        self.deaths: deque[float] = deque()   # when started workers died (monotonic s), within the window
        self.restarts = 0
        root = Path(tempfile.gettempdir()) if logs_root is None else logs_root
        remove_orphaned_logs(root)
        self._logs = tempfile.TemporaryDirectory(prefix=f"{LOGS_PREFIX}{os.getpid()}-", dir=root)
        self._spawned = 0
        self.slots: list[_Slot] = [self._spawn() for _ in range(n)]

    @property
    def procs(self) -> list[tuple[subprocess.Popen, Path]]:
        return [(s.proc, s.log_path) for s in self.slots if s.proc is not None]

    def _spawn(self) -> _Slot:
        self._spawned += 1
        log_path = Path(self._logs.name) / f"worker-{self._spawned}.log"
        ready_path = Path(self._logs.name) / f"worker-{self._spawned}.ready"
        env = dict(os.environ, **{READY_ENV: str(ready_path)})
        with open(log_path, "wb") as err:
            proc = subprocess.Popen(self.command, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=err,
                                    env=env,
                                    preexec_fn=HELPER_PREEXEC)
        return _Slot(proc, log_path, ready_path)

    @staticmethod
    def _tail(path: Path, lines: int = 6) -> str:
        try:
            text = path.read_text(errors="replace").strip().splitlines()
        except OSError:
            return ""
        return "\n".join(text[-lines:])

    def _room(self, now: float) -> bool:
        while self.deaths and now - self.deaths[0] > self.death_window_s:
            self.deaths.popleft()
        return len(self.deaths) < self.death_budget

    def check(self) -> str | None:
        """Restart workers that exited; a reason to stop the search once workers cannot start at all."""
        now = time.monotonic()
        for i, slot in enumerate(self.slots):
            if slot.proc is None:  # a restart waiting for room in the death budget
                if self._room(now):
                    self.slots[i] = self._spawn()
                    self.restarts += 1
                continue
            if slot.ready_path.exists():
                self.start_failures = 0  # workers can start
            code = slot.proc.poll()
            if code is None:
                continue
            tail = self._tail(slot.log_path)
            if code == EXIT_UNSERVABLE:
                return f"a local worker cannot serve this run:\n{tail}"
            room = self._room(now)
            if slot.ready_path.exists():
                self.deaths.append(now)
            else:
                self.start_failures += 1
                if self.start_failures >= self.max_failures:
                    return (f"local workers cannot start ({self.start_failures} in a row exited before they were "
                            f"ready, last with code {code}); the last one said:\n{tail or '(nothing)'}")
            if room:
                self.slots[i] = self._spawn()
                self.restarts += 1
            else:
                slot.proc = None
        return None

    def stop(self, timeout_s: float = 10.0) -> None:
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
