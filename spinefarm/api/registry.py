"""Which run files the API serves: explicit files and/or every *.h5 in a directory (rescanned), each read once
per identity in a child process (storage.probe) whose verdict every request shares.

Under load the API must not lose a good run: the folder is looked at once per SCAN_INTERVAL_S for all
requests, a file has at most one read in flight, a read that runs out of time means "still reading" (a
busy machine), never "missing" (the last good state is kept and the file read again with a longer deadline),
and a run's status is built once per VIEW_INTERVAL_S and shared by the requests in that interval.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from spinefarm.api.errors import NotFound
from spinefarm.api.run_state import writer_holds
from spinefarm.protocol.errors import StorageError
from spinefarm.storage.probe import probe
from spinefarm.storage.status import status_path

PROBE_TIMEOUT_S = 5.0
# a file whose read ran out of time is read again with a longer deadline each time (5 s, then 10, 20, 30)
PROBE_MAX_TIMEOUT_S = 30.0
PARALLEL_PROBES = 4
RETRY_FIRST_S, RETRY_MAX_S = 5.0, 300.0
SCAN_INTERVAL_S = 1.0   # the folder and the files' identities, looked at once per interval for every request
VIEW_INTERVAL_S = 1.0   # a run's status entry, built once per interval and shared
FIRST_READ_WAIT_S = 60.0  # a request waits at most this long for the first reads of files it has not seen

log = logging.getLogger("spinefarm.api")


def _probe_or_error(path: Path, timeout_s: float = PROBE_TIMEOUT_S) -> tuple[str, StorageError | None]:
    if not path.is_file():
        return "", StorageError("no such file", received=str(path), expected="an existing run file")
    try:
        return probe(path, timeout_s), None
    except StorageError as exc:
        return "", exc


def _ran_out_of_time(error: StorageError | None) -> bool:
    return error is not None and ("did not finish within" in str(error) or "did not start within" in str(error))


def servable(files: list[Path]) -> tuple[list[Path], list[tuple[Path, StorageError]]]:
    """The files that open within the probe's deadline, and (file, error) for the others: a damaged file
    named on the command line is skipped as one in `--runs-dir` is, never read in the server."""
    with ThreadPoolExecutor(max_workers=PARALLEL_PROBES) as pool:
        results = list(pool.map(_probe_or_error, files))
        late = [i for i, (_, err) in enumerate(results) if _ran_out_of_time(err)]
        # once more with the longest deadline: the server must not drop a healthy file for a busy start
        again = pool.map(lambda i: _probe_or_error(files[i], PROBE_MAX_TIMEOUT_S), late)
        for i, result in zip(late, again, strict=True):
            results[i] = result
    ok = [f for f, (_, err) in zip(files, results, strict=True) if err is None]
    return ok, [(f, err) for f, (_, err) in zip(files, results, strict=True) if err is not None]


@dataclass
class _File:
    """What the registry knows of one path, for the file identity (device, inode) it was read as."""

    ident: tuple[int, int]
    mark: tuple[int, int, int, int]       # identity, size and mtime at the last look
    run_id: str | None = None             # the last good read's run id: kept while a new read is slow
    error: str | None = None              # the last read's error (damaged, or out of time)
    damaged: bool = False                 # read and found damaged, not merely slow
    reads: int = 0                        # reads finished for this identity
    future: Future | None = None          # the one read in flight
    deadline_s: float = PROBE_TIMEOUT_S
    retry_at: float = 0.0                 # monotonic time of the next read after running out of time
    backoff_s: float = RETRY_FIRST_S / 2
    set_aside: str | None = None          # why its status could not be shown (cleared when it can)


def _looks(path: Path) -> tuple[Any, ...]:
    """What changes a run's status at once, cheaply: the run file replaced (resume, compress at close), a
    status file appearing or going, a writer taking or leaving the run. A live run's rows and status file
    change at every flush: those wait for the interval."""
    try:
        inode = path.stat().st_ino
    except OSError:
        inode = 0
    return inode, status_path(path).exists(), writer_holds(path)


@dataclass
class _View:
    at: float = -1e18
    looks: tuple[Any, ...] = ()
    value: dict[str, Any] | None = None
    lock: threading.Lock = field(default_factory=threading.Lock)


class RunRegistry:
    """The served files and their state, shared by every request (see the module's doc)."""

    def __init__(self, files: list[Path], runs_dir: Path | None) -> None:
        self.files = [Path(f) for f in files]
        self.runs_dir = Path(runs_dir) if runs_dir is not None else None
        self._known: dict[Path, _File] = {}
        self._views: dict[Path, _View] = {}
        self._lock = threading.RLock()  # a read done at once calls _apply in the thread that started it
        self._scanned_at = -1e18
        self._pool = ThreadPoolExecutor(max_workers=PARALLEL_PROBES, thread_name_prefix="probe")

    def close(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)

    def paths(self) -> list[Path]:
        found = list(self.files)
        if self.runs_dir is not None and self.runs_dir.is_dir():
            found += sorted(p for p in self.runs_dir.glob("*.h5") if p not in found)
        return found

    def runs(self) -> dict[str, Path]:
        """run id -> path of every file read good (a slow re-read keeps it); waits only for the first reads of
        files never seen before."""
        with self._lock:
            if time.monotonic() - self._scanned_at >= SCAN_INTERVAL_S:
                self._scan()
                self._scanned_at = time.monotonic()
            first = [f.future for f in self._known.values() if f.future is not None and f.reads == 0
                     and f.run_id is None]
        if first:
            wait(first, timeout=FIRST_READ_WAIT_S)
        out: dict[str, Path] = {}
        with self._lock:
            for p, f in self._known.items():
                if f.run_id is not None and not f.damaged:
                    out.setdefault(f.run_id, p)
        return out

    def _scan(self) -> None:
        present = self.paths()
        for p in set(self._known) - set(present):
            del self._known[p]
        now = time.monotonic()
        for p in present:
            try:
                st = p.stat()
            except OSError:
                self._known.pop(p, None)
                continue
            ident = (st.st_dev, st.st_ino)  # resume or compress-at-close replace the file: read anew
            mark = (*ident, st.st_size, st.st_mtime_ns)
            f = self._known.get(p)
            if f is None or f.ident != ident:
                kept = f.run_id if f is not None and not f.damaged else None
                f = self._known[p] = _File(ident, mark, run_id=kept)
                self._read(p, f)
            elif f.damaged and f.mark != mark:  # changed since it was found damaged: perhaps repaired
                f.mark = mark
                self._read(p, f)
            elif f.error and not f.damaged and f.future is None and now >= f.retry_at:
                self._read(p, f)  # it ran out of time: again, with a longer deadline
            f.mark = mark

    def _read(self, p: Path, f: _File) -> None:
        if f.future is not None:
            return  # one read per file at a time, whatever the number of requests
        f.future = self._pool.submit(_probe_or_error, p, f.deadline_s)
        f.future.add_done_callback(lambda fut: self._apply(p, f, *fut.result()))

    def _apply(self, p: Path, f: _File, run_id: str, error: StorageError | None) -> None:
        with self._lock:
            f.future, f.reads = None, f.reads + 1
            if error is None:
                f.run_id, f.error, f.damaged = run_id, None, False
                f.deadline_s, f.backoff_s = PROBE_TIMEOUT_S, RETRY_FIRST_S / 2
                return
            f.error = str(error)
            if _ran_out_of_time(error):  # a busy machine, or a hanging file: still reading, not missing
                f.backoff_s = min(RETRY_MAX_S, 2 * f.backoff_s)
                f.retry_at = time.monotonic() + f.backoff_s
                f.deadline_s = min(PROBE_MAX_TIMEOUT_S, 2 * f.deadline_s)
                log.warning("still reading %s%s: %s", p, " (its last good state is served)" if f.run_id else "",
                            error)
            else:
                f.damaged, f.run_id = True, None
                log.warning("leaving out %s: %s", p, error)

    def damaged(self) -> list[tuple[Path, str]]:
        """Files not served (damaged, or not read yet because their reads run out of time) and those whose
        status cannot be shown now, and why, in path order."""
        with self._lock:
            out = [(p, f.error) for p, f in self._known.items() if f.error and (f.damaged or f.run_id is None)]
            out += [(p, f.set_aside) for p, f in self._known.items() if f.set_aside and not f.damaged]
        return sorted(out)

    def path_of(self, run_id: str) -> Path:
        runs = self.runs()
        if run_id not in runs:
            raise NotFound("no such run", received=run_id, expected=f"one of {sorted(runs)[:20]}")
        return runs[run_id]

    def view(self, path: Path, build: Callable[[], dict[str, Any]]) -> dict[str, Any]:
        """`build()` (a run's status entry), shared by the requests until VIEW_INTERVAL_S has passed or its
        files or writer change; an error is noted (damaged()) and raised."""
        with self._lock:
            v = self._views.setdefault(path, _View())
        with v.lock:  # one build at a time; those waiting take its result
            looks = _looks(path)
            if time.monotonic() - v.at < VIEW_INTERVAL_S and v.looks == looks and v.value is not None:
                return v.value
            try:
                v.value, v.at, v.looks = build(), time.monotonic(), looks
            except Exception as exc:
                self._note(path, f"its status cannot be read now: {str(exc).splitlines()[0][:300]}")
                raise
        self._note(path, None)
        return v.value

    def _note(self, path: Path, why: str | None) -> None:
        with self._lock:
            if path in self._known:
                self._known[path].set_aside = why
