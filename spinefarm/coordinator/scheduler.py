"""Leases: which worker holds which trial until when; re-issue on expiry or worker loss.

Time comes from an injected clock (seconds, monotonic), so tests move time instead of sleeping.
A lease is identified by (trial_id, lease_id); each re-issue of a trial gets a new lease_id, so a
result quoting an old lease is recognised as stale. Lease ids are 62 random bits, known only to the
worker the lease went to (a query's reply reaches only its querier) and valid only with that worker's
id: a peer cannot guess one, and one it did not receive counts as forged.

Bounds against a greedy or broken worker: at most `max_grant` trials per request and per worker at a
time; the i-th lease of a batch lasts lease_s + i x the expected trial time (not (i + 1) x lease_s);
a trial whose lease is lost `max_attempts` times (it keeps killing or freezing its workers) is given
up and handed to the caller to be stored as failed.

A re-issued trial goes to a worker that has not failed it yet: one it timed out or crashed on (`retry`)
gets it again only when no other live worker may run it (then the cap still ends it); one whose lease
expired or whose worker vanished gets it only once it has nothing else to run (no queued trial, no new
one), or when no other live worker may run it. "Live": its liveliness token is up and it spoke within
lease_s (a worker that never asks does not hold a trial back). For `start_grace_s` after the scheduler
starts, while workers are still (re)connecting, a timed-out or crashed trial waits for another worker
rather than going back to the only one known. Kept in memory with the attempt count, so both start
again after a coordinator restart.

A worker asking for work without trials it holds never got or could not run their grant: they are issued again
first (`take_back_unreported`), and after MAX_UNREPORTED such asks in a row they go to other workers; the worker
then gets one trial per lease_s, lost as a silent worker's lease is, until it returns a result.
"""

from __future__ import annotations

import heapq
import logging
import secrets
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from spinefarm.protocol.errors import check_range

log = logging.getLogger("spinefarm.coordinator")
MAX_GRANT = 64       # trials per request and per worker at a time
MAX_ATTEMPTS = 3     # lost leases before a trial is stored as failed
_TRIAL_TIME_MARGIN = 4.0
START_GRACE_S = 10.0  # after a (re)start, workers reconnect within a few seconds
# Asks in a row without the trials a worker was granted before they go to others: one lost reply happens (a query
# timed out under load), three in a row (~5 s at a worker's back-off) is a worker that cannot get or run its grants.
MAX_UNREPORTED = 3


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
    unreported: int = 0   # asks in a row without trials it was granted (reset when it returns one)
    probe_after_s: float = 0.0   # while unreported >= max_unreported: when it may be granted a trial again


class Scheduler:
    """Not thread-safe: the coordinator calls it under its own lock."""

    def __init__(self, clock: Callable[[], float], lease_s: float = 60.0, *, max_grant: int = MAX_GRANT,
                 max_attempts: int = MAX_ATTEMPTS, start_grace_s: float = START_GRACE_S,
                 max_unreported: int = MAX_UNREPORTED) -> None:
        check_range("lease_s", lease_s, 0.0, low_inclusive=False)
        check_range("max_grant", max_grant, 1)
        check_range("max_attempts", max_attempts, 1)
        check_range("max_unreported", max_unreported, 1)
        self.clock = clock
        self.lease_s = float(lease_s)
        self.max_grant = int(max_grant)
        self.max_attempts = int(max_attempts)
        self.max_unreported = int(max_unreported)
        self.grace_until_s = clock() + start_grace_s
        self.expected_trial_s = self.lease_s       # until trials are measured (observe_trial)
        self._measured = False
        self._queue: deque[int] = deque()          # trials waiting to be (re-)issued
        self._leases: dict[int, Lease] = {}        # trial id -> its current lease
        self._deadlines: list[tuple[float, int, int]] = []  # heap (deadline, trial, lease); lazy deletion
        self._issued: dict[int, dict[int, str]] = {}  # unfinished trial -> {lease id: worker} ever issued
        self._attempts: dict[int, int] = {}        # unfinished trial -> leases lost so far
        self._failed_on: dict[int, dict[str, bool]] = {}  # unfinished trial -> {worker: it timed out/crashed there}
        self.given_up: list[tuple[int, str]] = []  # (trial, reason) to be stored as failed by the caller
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

    def observe_trial(self, wall_time_s: float) -> None:
        """A stored trial took this long on its worker: batches get leases sized to it."""
        if wall_time_s > 0 and wall_time_s == wall_time_s:
            t = min(self.lease_s, _TRIAL_TIME_MARGIN * wall_time_s)
            self.expected_trial_s = (0.8 * self.expected_trial_s + 0.2 * t) if self._measured else t
            self._measured = True

    def grant(self, worker_id: str, capacity: int, new_trial: Callable[[], int | None],
              eligible: Callable[[int, str], bool] | None = None) -> list[Lease]:
        """Lease up to `capacity` trials (at most max_grant, counting those the worker holds already):
        queued ones this worker may run first (`eligible(key, worker)`: e.g. it runs their engine, or
        it is not the worker an audit checks), then new ones from `new_trial` (None = none; a new one
        the worker may not run is queued for another).

        The i-th lease of a batch gets lease_s + i x expected_trial_s, as the worker runs its batch in order.
        """
        now = self.clock()
        self.expire()
        worker = self.contact(worker_id)
        capacity = min(capacity, self.max_grant - len(worker.leases))
        suspect = worker.unreported >= self.max_unreported   # its grants do not reach it, or it cannot run them
        if suspect:  # one trial per lease_s, none it lost that others could take: it may have come right
            capacity = 0 if worker.leases or now < worker.probe_after_s else min(capacity, 1)
        ok = eligible or (lambda key, wid: True)
        out: list[Lease] = []
        fresh = True   # new trials may still come (before a trial this worker lost goes back to it)
        while len(out) < capacity:
            tid = self._next_queued(worker_id, ok, now, again=False)
            if tid is None and fresh:
                tid = new_trial()
                if tid is not None and not ok(tid, worker_id):
                    self._queue.append(tid)
                    tid = None
                fresh = tid is not None
            if tid is None and not suspect:
                tid = self._next_queued(worker_id, ok, now, again=True)
            if tid is None:
                break
            lease_id = secrets.randbits(62)
            lease = Lease(tid, lease_id, worker_id, now + self.lease_s + self.expected_trial_s * len(out))
            self._issued.setdefault(tid, {})[lease_id] = worker_id
            self._leases[tid] = lease
            heapq.heappush(self._deadlines, (lease.deadline_s, tid, lease.lease_id))
            worker.leases.add(tid)
            out.append(lease)
        if suspect and out:
            worker.probe_after_s = now + self.lease_s
        return out

    def _next_queued(self, worker_id: str, ok: Callable[[int, str], bool], now: float, *,
                     again: bool) -> int | None:
        """The first queued key this worker may run, taken out of the queue (the others keep their order).
        again=False: only keys it has not failed, or failed with no other live worker to take them;
        again=True: also keys whose lease it lost (expired, vanished) while others could take them."""
        for i, key in enumerate(self._queue):
            if ok(key, worker_id) and self._may_take(key, worker_id, ok, now, again):
                del self._queue[i]
                return key
        return None

    def _may_take(self, key: int, worker_id: str, ok: Callable[[int, str], bool], now: float,
                  again: bool) -> bool:
        failed = self._failed_on.get(key)
        if not failed or worker_id not in failed:
            return True
        if again and not failed[worker_id]:
            return True
        live = [w.worker_id for w in self.workers.values() if w.alive and now - w.last_contact_s <= self.lease_s
                and ok(key, w.worker_id)]
        if any(w not in failed for w in live) or now < self.grace_until_s:
            return False
        if failed[worker_id]:
            log.warning("trial %s goes back to worker %s, which it timed out or crashed on: no other live worker "
                        "may run it (live: %s)", key, worker_id, ", ".join(live) or "none")
        return True

    def failed_on(self, key: int) -> list[str]:
        """Workers this unfinished trial has timed out, crashed or lost its lease on, in that order."""
        return list(self._failed_on.get(key, {}))

    def push_front(self, key: int) -> None:
        """Issue `key` (a task) before anything queued."""
        if key not in self._queue and key not in self._leases:
            self._queue.appendleft(key)

    def queued(self, key: int) -> bool:
        return key in self._queue

    def withdraw(self, key: int) -> None:
        """Forget `key` whether queued or leased: a late result for it is stale (its issue is remembered)."""
        if key in self._queue:
            self._queue.remove(key)
        self._drop_lease(key)
        self._attempts.pop(key, None)
        self._failed_on.pop(key, None)

    def take_back(self, worker_id: str) -> list[int]:
        """Withdraw every key `worker_id` holds (withdraw: no attempt counted) and issue them before anything
        queued, in the order of their keys."""
        w = self.workers.get(worker_id)
        keys = sorted(w.leases) if w is not None else []
        for key in reversed(keys):
            self.withdraw(key)
            self.push_front(key)
        return keys

    def take_back_unreported(self, worker_id: str) -> tuple[list[int], bool]:
        """The worker asks for work without results of keys it holds: (keys taken back, whether they are barred).
        Below max_unreported asks in a row they are taken back and issued first again (a lost reply: it may
        well be the asker that gets them). At the max_unreported-th they are taken back and barred: counted as
        lost on it, they go to other live workers first. Beyond it the worker keeps failing: what it holds is lost
        as a silent worker's lease is (an attempt counted, max_attempts end it), at once rather than at its
        deadline, and it is granted one trial per lease_s ([], False: nothing more to say)."""
        w = self.workers.get(worker_id)
        if w is None or not w.leases:
            return [], False
        w.unreported += 1
        if w.unreported > self.max_unreported:
            self._reissue(sorted(w.leases), f"worker {worker_id} asked for work without it")
            return [], False
        keys = self.take_back(worker_id)
        barred = w.unreported == self.max_unreported
        for key in keys if barred else ():
            self._failed_on.setdefault(key, {})[worker_id] = False
        return keys, barred

    def _answered(self, key: int) -> None:
        """The holder of `key`'s lease returned it (stored, or given back failed): it gets its grants."""
        lease = self._leases.get(key)
        if lease is not None and lease.worker_id in self.workers:
            self.workers[lease.worker_id].unreported = 0

    def is_current(self, trial_id: int, lease_id: int, worker_id: str) -> bool:
        lease = self._leases.get(trial_id)
        return lease is not None and lease.lease_id == lease_id and lease.worker_id == worker_id

    def was_issued(self, trial_id: int, lease_id: int, worker_id: str) -> bool:
        """This lease went to this worker at some point (a late result, not a forged one)."""
        return self._issued.get(trial_id, {}).get(lease_id) == worker_id

    def _drop_lease(self, trial_id: int) -> None:
        lease = self._leases.pop(trial_id, None)
        if lease is not None and lease.worker_id in self.workers:
            self.workers[lease.worker_id].leases.discard(trial_id)

    def release(self, trial_id: int) -> None:
        """The trial's result was stored: forget its lease and its history."""
        self._answered(trial_id)
        self._drop_lease(trial_id)
        self._issued.pop(trial_id, None)
        self._attempts.pop(trial_id, None)
        self._failed_on.pop(trial_id, None)

    def _reissue(self, trial_ids: list[int], why: str, *, hard: bool = False) -> None:
        """Put trials at the head of the queue, in order: re-issues go before new trials; a trial that
        lost its lease max_attempts times goes to `given_up` instead. Each lease's worker is remembered
        as one that failed the trial (hard: it timed out or crashed there)."""
        again = []
        for tid in trial_ids:
            lease = self._leases.get(tid)
            if lease is not None:
                failed = self._failed_on.setdefault(tid, {})
                failed[lease.worker_id] = failed.get(lease.worker_id, False) or hard
            self._drop_lease(tid)
            n = self._attempts[tid] = self._attempts.get(tid, 0) + 1
            if n >= self.max_attempts:
                given = f"{why[:120]} ({n} attempts)" if hard else f"lost its worker {n} times (last: {why})"
                self.given_up.append((tid, given + self._on_whom(tid)))
                self._issued.pop(tid, None)
                self._attempts.pop(tid, None)
                self._failed_on.pop(tid, None)
            else:
                again.append(tid)
        self._queue.extendleft(reversed(again))
        self.reissued += len(again)

    def retry(self, trial_id: int, why: str) -> None:
        """The lease holder gave the trial back unfinished (it timed out or crashed its simulator there):
        re-queued like a lost lease, and given up after max_attempts with `why` leading its reason."""
        self._answered(trial_id)
        self._reissue([trial_id], why, hard=True)

    def _on_whom(self, key: int) -> str:
        """' on 2 workers: w1, w2': the distinct workers the trial failed on, for its reason."""
        names = self.failed_on(key)
        text = ", ".join(n[:24] for n in names)
        return f" on {len(names)} worker{'s' if len(names) != 1 else ''}: {text}" if names else ""

    def expire(self) -> list[int]:
        """Re-queue every trial whose lease deadline has passed; returns their ids."""
        now = self.clock()
        out = []
        while self._deadlines and self._deadlines[0][0] <= now:
            _, tid, lease_id = heapq.heappop(self._deadlines)
            lease = self._leases.get(tid)
            if lease is not None and lease.lease_id == lease_id:
                out.append(tid)
        self._reissue(out, f"lease expired after {self.lease_s:g} s")
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

    def speaking(self, worker_id: str) -> bool:
        """The worker is live: its liveliness token is up and it spoke within lease_s."""
        w = self.workers.get(worker_id)
        return w is not None and w.alive and self.clock() - w.last_contact_s <= self.lease_s

    def worker_lost(self, worker_id: str) -> list[int]:
        """The worker's liveliness token vanished: re-queue its leases at once."""
        w = self.workers.get(worker_id)
        if w is None:
            return []
        w.alive = False
        lost = sorted(w.leases)
        self._reissue(lost, f"worker {worker_id} vanished")
        return lost
