"""What a worker's loop paces itself by, engine- and transport-free: back-off while the coordinator is
absent, batch sizes, telling a refused session from an unreachable one, and its ready file."""

from __future__ import annotations

import logging
import os
import random
import re
import socket
import uuid
from collections.abc import Sequence
from pathlib import Path

log = logging.getLogger("spinefarm.worker")
READY_ENV = "SPINEFARM_READY_FILE"   # as cli.local_workers names it
EXIT_REFUSED = 4   # the router refused this worker's session (with --exit-when-done)


def listening_endpoints(endpoints: Sequence[str], timeout_s: float = 1.0) -> list[str]:
    """The TCP-based endpoints (tcp/, tls/) where something accepts a connection: a session that still
    fails there was refused, not left unanswered."""
    out = []
    for ep in endpoints:
        m = re.fullmatch(r"(tcp|tls)/\[?([^\]]+?)\]?:(\d+)(#.*)?", ep)
        if m is None:
            continue
        try:
            with socket.create_connection((m.group(2), int(m.group(3))), timeout=timeout_s):
                out.append(ep)
        except OSError:
            continue
    return out


def mark_ready(worker_id: str) -> None:
    """Tell a supervising `search` (cli.local_workers) that this worker has started: a later exit is a
    death, not a start failure."""
    path = os.environ.get(READY_ENV)
    if path:
        try:
            Path(path).write_text(worker_id + "\n")
        except OSError as exc:
            log.warning("cannot write the ready file %s: %s", path, exc.strerror)


def default_worker_id() -> str:
    host = "".join(ch if ch.isalnum() or ch in "-_." else "-" for ch in socket.gethostname())[:32]
    return f"{host or 'worker'}-{os.getpid()}-{uuid.uuid4().hex[:6]}"


class Backoff:
    """Exponential wait between retries while the coordinator is absent, each wait drawn at random from the
    upper half of its step. Without the draw, workers whose queries a dead coordinator's session held all fail
    at the moment the router drops that session and then ask in step: a restarted coordinator met hundreds of
    first requests at once (bench/scale.py --restart)."""

    def __init__(self, first_s: float = 0.05, max_s: float = 2.0, rng: random.Random | None = None) -> None:
        self.first_s, self.max_s, self._next = first_s, max_s, first_s
        self._rng = rng or random.Random()

    def next(self) -> float:
        wait, self._next = self._next, min(self._next * 2, self.max_s)
        return wait * self._rng.uniform(0.5, 1.0)

    def reset(self) -> None:
        self._next = self.first_s


class BatchSizer:
    """Trials to ask for: a fixed number, or (auto) about `target_s` of work by the mean trial time.

    Slow physics trials go one at a time (a lost worker strands little work); microsecond test trials
    go in large batches, so round trips do not dominate.
    """

    def __init__(self, fixed: int | None, target_s: float = 0.5, max_batch: int = 64) -> None:
        self.fixed, self.target_s, self.max_batch = fixed, target_s, max_batch
        self._mean_s: float | None = None

    def observe(self, wall_time_s: float) -> None:
        self._mean_s = wall_time_s if self._mean_s is None else 0.8 * self._mean_s + 0.2 * wall_time_s

    def size(self) -> int:
        if self.fixed is not None:
            return self.fixed
        if self._mean_s is None:
            return 1
        return max(1, min(self.max_batch, int(self.target_s / max(self._mean_s, 1e-6))))
