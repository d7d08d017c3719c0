"""Nothing simulated twice: a trial's end kept, so that a longer trial of the same parameter set goes on from it.

A rung of a multi-fidelity search is exactly the first seconds of the longer trial its promotion runs (a trial's bits
do not depend on its length, docs/performance.md), and an engine that can snapshot a world (MuJoCo: a copy of its
MjData) restores it with the bits of a trial that never stopped. So a worker keeps the end of each one-world trial
it runs: the engine's snapshot, the control law's, and the trial's measurements so far (COM path, last sane check,
settle pose and work: worker.trial.batch.WorldLog). A later trial whose key is the same (everything its bits depend
on besides its length) and that runs at least as many steps starts from that end instead of step 0, and ends in the
same bits as one run from the start. Bullet cannot restore a world exactly (a rebuilt world's contact caches are
not the old world's, see worker.trial.setup), so its trials always run from the start.

The key is taken within one TrialSetup (robot, trial config but its per-trial fields, engine, its options and step,
controller): the settle and check periods in steps, the CPG's update interval, the start offsets (the seeded pose
jitter, if any) and the parameter set's physical values.
"""

from __future__ import annotations

import copy
import hashlib
from dataclasses import dataclass
from typing import Any

import numpy as np

from spinefarm.worker.trial.lru import LRU

# ends kept per set-up (an LRU by count): an end of the Tetraspine's 5 s rung at 2 ms after a 1 s settle is ~40 kB
# (its MuJoCo integration state ~1 kB, the law's ~5 kB, the COM path of its checks; `python bench/continue_rungs.py`
# prints `end_bytes`), so about 40 MB at most; in its search of 2 workers a promotion came at most 41 rows after its
# rung, and one whose end was dropped is simulated from the start (the same bits)
DEFAULT_ENDS = 1024


@dataclass
class RungEnd:
    """One world at the end of a trial: the engine's snapshot, the law's (ControlLaw.snapshot), the trial's
    measurements so far (a WorldLog) and the steps taken since the start, settle included."""

    engine_state: Any
    law_state: tuple[np.ndarray, ...]
    world: Any
    done: int

    def world_copy(self) -> Any:
        return copy.deepcopy(self.world)


def end_key(n_settle: int, check_every: int, cpg_every: int, offsets_cm: np.ndarray | None,
            physical: np.ndarray) -> str:
    """What a trial's bits depend on within its set-up, besides its length (see the module)."""
    h = hashlib.sha256()
    h.update(np.array([n_settle, check_every, cpg_every], dtype=np.int64).tobytes())
    h.update(b"none" if offsets_cm is None else np.ascontiguousarray(offsets_cm, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(physical, dtype=np.float64).tobytes())
    return h.hexdigest()


class RungEnds(LRU[str, RungEnd]):
    """Trial ends by end_key, the `size` most recently used kept (worker.trial.lru)."""

    def __init__(self, size: int = DEFAULT_ENDS) -> None:
        super().__init__(size, "kept trial ends")

    def get(self, key: str, total_steps: int) -> RungEnd | None:  # type: ignore[override]
        """The kept end of `key` if the trial asking runs at least as far (total_steps, settle included)."""
        return super().get(key, lambda end: end.done <= total_steps)
