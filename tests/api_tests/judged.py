"""Judged run files written through the storage API as the coordinator stores them, shared by the judged-COT,
model-spread and compare tests: trials screened in MuJoCo, some judged in Bullet at 0.25 ms, other rows (an
opinion, an audit) added by the caller."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.settings import JudgePolicy, Rung
from spinefarm.protocol.states import AuditState, Verification
from spinefarm.storage.evaluations import row_of
from spinefarm.storage.hdf5 import Hdf5Storage
from tests.storage_tests.conftest import make_meta, result

# a run file of schema 8, written by spinefarm at ce6864d (tests/api_tests/test_judged_cot.py says what it holds)
OLD = Path(__file__).parents[1] / "storage_tests" / "data" / "run-schema8.h5"
JUDGE_ENGINE, JUDGE_DT_S = "bullet", 2.5e-4

# run-c (test_judged_cot.py): trial -> (distance m, COT)
SCREEN = {0: (0.05, 1.1), 1: (0.30, 2.2), 2: (0.02, 3.3), 3: (0.21, 4.4)}
JUDGE = {1: (0.40, 5.5), 3: (0.25, 6.6)}     # Bullet at 0.25 ms judges trials 1 and 3
OPINION = {1: (0.32, 7.7)}                    # MuJoCo at 1 ms, the other engine's run of trial 1
AUDIT = {1: (0.30, 8.8)}                      # another worker, the screen's fidelity


@contextmanager
def judged_run(path: Path, run_id: str, screen: Mapping[int, TrialResult], judge: Mapping[int, TrialResult],
               **settings: object) -> Iterator[Hdf5Storage]:
    """A run file of trials screened in MuJoCo (trial id -> its result) and judged in Bullet at 0.25 ms (trial id ->
    the judge's result), run settings besides the judge's given by keyword; open for more rows, closed after."""
    meta = make_meta(run_id, budget=len(screen))
    meta = dataclasses.replace(
        meta, settings=dataclasses.replace(meta.settings, judge=JudgePolicy(rung=Rung(JUDGE_ENGINE, JUDGE_DT_S)),
                                           **settings),
        run={**meta.run, "trial_config": {"duration_s": 0.5, "engine": "mujoco"}})
    s = Hdf5Storage.create(path, meta)
    try:
        for tid, measured in screen.items():
            s.add_trial(tid, np.full(3, 0.5), np.zeros(3), "monte_carlo", -1, tid)
            s.finish_trial(tid, measured, measured.distance_m)
        for tid, measured in judge.items():
            s.add_evaluation(row_of(tid, "judge", measured, JUDGE_ENGINE, JUDGE_DT_S, "w-judge"))
            s.set_verification(tid, Verification.JUDGED, measured.distance_m, f"judged in {JUDGE_ENGINE}",
                               screen[tid].distance_m / measured.distance_m)
        yield s
    finally:
        s.close()


def result_with_cot(tid: int, distance_m: float, cot: float) -> TrialResult:
    return dataclasses.replace(result(tid, distance_m), cot=cot)


def write_cot_run(path: Path) -> None:
    """run-c: SCREEN, JUDGE, OPINION and AUDIT above, each row with its own COT."""
    with judged_run(path, "run-c", {t: result_with_cot(t, *v) for t, v in SCREEN.items()},
                    {t: result_with_cot(t, *v) for t, v in JUDGE.items()}) as s:
        for tid, (d, cot) in OPINION.items():
            s.add_evaluation(row_of(tid, "opinion", result_with_cot(tid, d, cot), "mujoco", 1e-3, "w-opinion"))
        for tid, (d, cot) in AUDIT.items():
            s.add_evaluation(row_of(tid, "audit", result_with_cot(tid, d, cot), "", None, "w-audit"))
            s.set_audit(tid, AuditState.AGREES, d, "w-audit")
