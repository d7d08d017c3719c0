"""The progress line of a search whose objective trades COT gives a judged best's speed and COT from the judge's
run, not the screen's. In-process core, a real run file, the Tetraspine's trials run by the worker's own
evaluator (Bullet; the judge at the finer step)."""

from __future__ import annotations

import math

from spinefarm.cli.report import progress
from spinefarm.coordinator.problem import build_run_config
from spinefarm.coordinator.setup import SearchSettings, new_run
from spinefarm.protocol.settings import JudgePolicy
from spinefarm.protocol.work import WorkGrant
from spinefarm.worker.service.zenoh_worker import build_evaluator
from tests.coordinator_tests.helpers import FakeClock
from tests.coordinator_tests.test_verification import _grant, _run, _submit


def test_a_judged_best_shows_the_judges_speed_and_cot_in_the_progress_line(tmp_path):
    config = build_run_config("progress-cot", "tetraspine-ntrt", objective="cot_distance", seed=3, duration_s=1.0)
    settings = SearchSettings(trials=2, startup_trials=2, judge=JudgePolicy(share=1.0, opinion=None))
    core, storage = new_run(config, settings, tmp_path / "run.h5", FakeClock())
    evaluate = build_evaluator(config)
    try:
        _submit(core, "w1", _run(evaluate, _grant(core, "w1", 2), "w1"))
        judged = {}
        while not core.done:   # a judged set may rank below the other one: that one is judged in turn
            [judge] = _grant(core, "w1", 1).assignments
            assert judge.fidelity.task == "judge"
            [ran] = _run(evaluate, WorkGrant("r", "h", (judge,)), "w1")
            _submit(core, "w1", (ran,))
            judged[judge.trial_id] = ran.result   # the worker's own measurement at the judge's step
        [tid] = storage.best_ids(1)
        best = storage.trial(tid)
        assert best.verification in ("holds", "moved")
        line = progress(core)[3]
    finally:
        storage.close()
    judge = judged[tid]
    speed_cm_s = 100 * judge.distance_m / judge.sim_time_s
    assert f"best {judge.distance_m:.3f} m judged ({speed_cm_s:.3g} cm/s, COT {judge.cot:.3g} (judged))" in line
    assert not math.isclose(judge.cot, best.cot, rel_tol=1e-3), (judge.cot, best.cot)   # the screen's differs
