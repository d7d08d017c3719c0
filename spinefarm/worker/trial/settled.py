"""The settled start: a settle phase (the CPG held at rest, worker.trial.batch) does not depend on the parameter set,
only on the robot, the engine and its settings, the step, the scene, the start pose and the string tables, all
fixed by a trial set-up (worker.trial.setup) and the key below. So it is simulated once, its end kept (in process,
with the set-up), and every later trial of the same key starts from it: the same bits as settling again, on
engines that can snapshot a world ("snapshot" in robot.engines).
"""

from __future__ import annotations

import copy
import hashlib
from dataclasses import dataclass
from typing import Any

import numpy as np

from spinefarm.worker.sim import strings as sk
from spinefarm.worker.trial.lru import LRU


@dataclass
class Settled:
    """One world at the end of its settle phase: the engine's snapshot of it, its string state (s, N_STATE), its
    reel-in work (internal units), its measurements so far (a worker.trial.batch.WorldLog) and the steps taken."""

    engine_state: Any
    string_state: np.ndarray
    work: float
    world: Any
    done: int

    def world_copy(self) -> Any:
        return copy.deepcopy(self.world)


def settle_key(n_settle: int, check_every: int, offsets_cm: np.ndarray | None, params: np.ndarray,
               state: np.ndarray) -> str:
    """What a settle phase depends on beyond its set-up: its length and check period (steps), the start offsets
    (nb, 3) cm and the world's string tables (params (s, N_PARAM) without the CPG node a string follows, which
    is held at rest, and initial state (s, N_STATE))."""
    h = hashlib.sha256()
    h.update(np.array([n_settle, check_every], dtype=np.int64).tobytes())
    h.update(b"none" if offsets_cm is None else np.ascontiguousarray(offsets_cm, dtype=np.float64).tobytes())
    fixed = np.delete(params, sk.P_NODE, axis=1)
    h.update(np.ascontiguousarray(fixed, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(state, dtype=np.float64).tobytes())
    return h.hexdigest()


class SettledStarts(LRU[str, Settled]):
    """Settled ends by settle_key, the `size` most recently used kept (worker.trial.lru)."""

    def __init__(self, size: int = 4) -> None:
        super().__init__(size, "kept settled starts")
