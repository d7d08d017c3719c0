"""Which run files the API serves: explicit files and/or every *.h5 in a directory (rescanned)."""

from __future__ import annotations

import logging
import math
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from spinefarm.api.errors import NotFound
from spinefarm.protocol.errors import StorageError
from spinefarm.storage.probe import probe

PROBE_TIMEOUT_S = 5.0
# a file whose read ran out of time is read again with a longer deadline each time (a busy machine starts a
# Python child slowly; a damaged file only costs more time in those few retries)
PROBE_MAX_TIMEOUT_S = 30.0
PARALLEL_PROBES = 4
RETRY_FIRST_S, RETRY_MAX_S = 5.0, 300.0


def _probe_or_error(path: Path, timeout_s: float = PROBE_TIMEOUT_S) -> tuple[str, StorageError | None]:
    if not path.is_file():
        return "", StorageError("no such file", received=str(path), expected="an existing run file")
    try:
        return probe(path, timeout_s), None
    except StorageError as exc:
        return "", exc


def _ran_out_of_time(error: StorageError | None) -> bool:
    return error is not None and "did not finish within" in str(error)

log = logging.getLogger("spinefarm.api")


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


class RunRegistry:
    """Each file is read once in a child process with a deadline (storage.probe) when first seen or
    replaced: a damaged file is left out (and logged), never read in the server, so it cannot hang
    requests for the healthy runs."""

    def __init__(self, files: list[Path], runs_dir: Path | None) -> None:
        self.files = [Path(f) for f in files]
        self.runs_dir = Path(runs_dir) if runs_dir is not None else None
        self._ids: dict[Path, tuple[tuple[int, int], str]] = {}   # path -> (file identity, run id)
        self._bad: dict[Path, tuple[int, int, int, int]] = {}     # path -> (identity, size, mtime) it failed with
        self._why: dict[Path, str] = {}                           # path -> why it was left out
        # a probe that ran out of time may only have met a busy machine: tried again later, less and less often
        self._retry: dict[Path, tuple[float, float]] = {}         # path -> (monotonic time of the retry, backoff)
        self._in_flight: set[Path] = set()                        # retried in the background right now
        self._background = ThreadPoolExecutor(max_workers=PARALLEL_PROBES, thread_name_prefix="probe-retry")
        self._lock = threading.Lock()

    def paths(self) -> list[Path]:
        found = list(self.files)
        if self.runs_dir is not None and self.runs_dir.is_dir():
            found += sorted(p for p in self.runs_dir.glob("*.h5") if p not in found)
        return found

    def runs(self) -> dict[str, Path]:
        seen: list[tuple[Path, tuple[int, int], tuple[int, int, int, int]]] = []
        retry: list[tuple[Path, tuple[int, int], tuple[int, int, int, int]]] = []
        for p in self.paths():
            try:
                st = p.stat()
            except OSError:
                continue
            ident = (st.st_dev, st.st_ino)  # resume replaces the file: a new inode is probed again
            mark = (*ident, st.st_size, st.st_mtime_ns)
            with self._lock:
                if self._bad.get(p) != mark:
                    seen.append((p, ident, mark))
                elif time.monotonic() >= self._retry.get(p, (math.inf, 0.0))[0] and p not in self._in_flight:
                    retry.append((p, ident, mark))
        for p, ident, mark in retry:  # off the request path: a damaged file never holds a request twice
            self._in_flight.add(p)
            future = self._background.submit(_probe_or_error, p, self._deadline(p))
            future.add_done_callback(lambda f, p=p, ident=ident, mark=mark: self._apply(p, ident, mark, *f.result()))
        new = [(p, ident, mark) for p, ident, mark in seen if p not in self._ids or self._ids[p][0] != ident]
        if new:  # each probe is a child process: several at once, so many new files cost one deadline
            with ThreadPoolExecutor(max_workers=PARALLEL_PROBES) as pool:
                results = list(pool.map(_probe_or_error, [p for p, _, _ in new]))
            for (p, ident, mark), (run_id, error) in zip(new, results, strict=True):
                self._apply(p, ident, mark, run_id, error)
        out: dict[str, Path] = {}
        with self._lock:
            for p, _, _ in seen:
                if p in self._ids and p not in self._bad:
                    out.setdefault(self._ids[p][1], p)
        return out

    def _apply(self, p: Path, ident: tuple[int, int], mark: tuple[int, int, int, int], run_id: str,
               error: StorageError | None) -> None:
        with self._lock:
            self._in_flight.discard(p)
            if error is None:
                self._ids[p] = (ident, run_id)
                for known in (self._bad, self._why, self._retry):
                    known.pop(p, None)
                return
            log.warning("leaving out %s: %s", p, error)
            self._bad[p] = mark
            self._why[p] = str(error)
            self._ids.pop(p, None)
            if _ran_out_of_time(error):
                backoff = min(RETRY_MAX_S, 2 * self._retry.get(p, (0.0, RETRY_FIRST_S / 2))[1])
                self._retry[p] = (time.monotonic() + backoff, backoff)
            else:
                self._retry.pop(p, None)

    def _deadline(self, path: Path) -> float:
        """A read again after running out of time waits twice as long as the wait before it (5 s, then 10, 20,
        ... up to PROBE_MAX_TIMEOUT_S): a busy machine starts the reading child slowly."""
        with self._lock:
            backoff = self._retry.get(path, (0.0, PROBE_TIMEOUT_S / 2))[1]
        return min(PROBE_MAX_TIMEOUT_S, max(PROBE_TIMEOUT_S, 2 * backoff))

    def damaged(self) -> list[tuple[Path, str]]:
        """Files left out (as of the last runs() call) and why, in path order."""
        present = set(self.paths())
        return sorted((p, why) for p, why in self._why.items() if p in self._bad and p in present)

    def path_of(self, run_id: str) -> Path:
        runs = self.runs()
        if run_id not in runs:
            raise NotFound("no such run", received=run_id, expected=f"one of {sorted(runs)[:20]}")
        return runs[run_id]
