"""Leases: which worker holds which trial until when; re-issue on expiry or worker loss.

Time comes from an injected clock (seconds, monotonic), so tests move time instead of sleeping.
A lease is identified by (trial_id, lease_id); each re-issue of a trial gets a new lease_id, so a
result quoting an old lease is recognised as stale.
"""

from __future__ import annotations

import heapq
import secrets
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from protocol.errors import check_range


@dataclass(frozen=True)
class Lease:
    trial_id: int
    lease_id: int
    worker_id: str
    deadline_s: float   # on the scheduler's clock


@dataclass
class WorkerState:
    worker_id: str
    alive: bool
    last_contact_s: float
    leases: set[int] = field(default_factory=set)


class Scheduler:
    """Not thread-safe: the coordinator calls it under its own lock."""

    def __init__(self, clock: Callable[[], float], lease_s: float = 60.0) -> None:
        check_range("lease_s", lease_s, 0.0, low_inclusive=False)
        self.clock = clock
        self.lease_s = float(lease_s)
        self._queue: deque[int] = deque()          # trials waiting to be (re-)issued
        self._leases: dict[int, Lease] = {}        # trial id -> its current lease
        self._deadlines: list[tuple[float, int, int]] = []  # heap (deadline, trial, lease); lazy deletion
        # Random start: lease ids of a restarted coordinator do not collide with its predecessor's.
        self._next_lease_id = secrets.randbits(40)
        self.workers: dict[str, WorkerState] = {}
        self.reissued = 0

    # --- state ------------------------------------------------------------------------------------
    @property
    def n_leased(self) -> int:
        return len(self._leases)

    @property
    def n_queued(self) -> int:
        return len(self._queue)

    def lease_of(self, trial_id: int) -> Lease | None:
        return self._leases.get(trial_id)

    # --- transitions ------------------------------------------------------------------------------
    def enqueue(self, trial_ids: list[int]) -> None:
        """Trials to issue before any new one (e.g. waiting trials found on resume)."""
        self._queue.extend(trial_ids)

    def grant(self, worker_id: str, capacity: int, new_trial: Callable[[], int | None]) -> list[Lease]:
        """Lease up to `capacity` trials: re-issues first, then new ones from `new_trial` (None = none).

        The i-th lease of a batch gets (i + 1) * lease_s, as the worker runs its batch in order.
        """
        now = self.clock()
        self.expire()
        worker = self.contact(worker_id)
        out: list[Lease] = []
        while len(out) < capacity:
            tid = self._queue.popleft() if self._queue else new_trial()
            if tid is None:
                break
            lease = Lease(tid, self._next_lease_id, worker_id, now + self.lease_s * (len(out) + 1))
            self._next_lease_id += 1
            self._leases[tid] = lease
            heapq.heappush(self._deadlines, (lease.deadline_s, tid, lease.lease_id))
            worker.leases.add(tid)
            out.append(lease)
        return out

    def is_current(self, trial_id: int, lease_id: int, worker_id: str) -> bool:
        lease = self._leases.get(trial_id)
        return lease is not None and lease.lease_id == lease_id and lease.worker_id == worker_id

    def release(self, trial_id: int) -> None:
        """The trial's result was stored: forget its lease."""
        lease = self._leases.pop(trial_id, None)
        if lease is not None and lease.worker_id in self.workers:
            self.workers[lease.worker_id].leases.discard(trial_id)

    def _reissue(self, trial_ids: list[int]) -> None:
        """Put trials at the head of the queue, in order: re-issues go before new trials."""
        for tid in trial_ids:
            self.release(tid)
        self._queue.extendleft(reversed(trial_ids))
        self.reissued += len(trial_ids)

    def expire(self) -> list[int]:
        """Re-queue every trial whose lease deadline has passed; returns their ids."""
        now = self.clock()
        out = []
        while self._deadlines and self._deadlines[0][0] <= now:
            _, tid, lease_id = heapq.heappop(self._deadlines)
            lease = self._leases.get(tid)
            if lease is not None and lease.lease_id == lease_id:
                out.append(tid)
        self._reissue(out)
        return out

    def contact(self, worker_id: str) -> WorkerState:
        """Note that a worker spoke to us (it is alive)."""
        now = self.clock()
        w = self.workers.get(worker_id)
        if w is None:
            w = self.workers[worker_id] = WorkerState(worker_id, True, now)
        w.alive = True
        w.last_contact_s = now
        return w

    def worker_lost(self, worker_id: str) -> list[int]:
        """The worker's liveliness token vanished: re-queue its leases at once."""
        w = self.workers.get(worker_id)
        if w is None:
            return []
        w.alive = False
        lost = sorted(w.leases)
        self._reissue(lost)
        return lost
