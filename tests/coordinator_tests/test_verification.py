"""No exploited physics: a new best is re-simulated by a worker (a judge task leased like any trial) before
it counts; the verdict says what happened."""

from __future__ import annotations

import dataclasses

import pytest

from spinefarm.coordinator.problem import build_run_config
from spinefarm.coordinator.setup import SearchSettings, new_run
from spinefarm.protocol.envelope import decode_message
from spinefarm.protocol.envelope import encode_message as enc
from spinefarm.protocol.settings import JudgePolicy
from spinefarm.protocol.submissions import ResultAck, ResultSubmission, SubmittedResult
from spinefarm.protocol.work import WorkGrant, WorkRequest
from spinefarm.storage.hdf5 import Hdf5Storage
from spinefarm.worker.service.zenoh_worker import build_evaluator
from tests.coordinator_tests.helpers import FakeClock


def _grant(core, worker: str, n: int) -> WorkGrant:
    return decode_message(core.handle_work(enc(WorkRequest(worker, n))), WorkGrant)


def _run(evaluate, grant: WorkGrant, worker: str) -> list[SubmittedResult]:
    """Run a grant's assignments as the worker's own evaluator does: the submissions, not yet sent."""
    return [SubmittedResult(a.lease_id, dataclasses.replace(evaluate(a), trial_id=a.trial_id, worker_id=worker,
                                                            seed=a.seed))
            for a in grant.assignments]


def _submit(core, worker: str, items) -> ResultAck:
    return decode_message(core.handle_results(enc(ResultSubmission(worker, tuple(items)))), ResultAck)


def test_a_bogus_best_is_not_reproduced_and_the_next_best_is_judged_by_a_worker(tmp_path):
    config = build_run_config("verify-run", "tetraspine-ntrt", seed=1, duration_s=1.0)
    settings = SearchSettings(trials=2, startup_trials=2, judge=JudgePolicy(tolerance=0.2))
    core, storage = new_run(config, settings, tmp_path / "run.h5", FakeClock())
    evaluate = build_evaluator(config)
    try:
        real, honest = _run(evaluate, _grant(core, "w1", 2), "w1")
        # trial 0 claims 5 m, as an exploded simulation would; trial 1 reports what it really did
        bogus = dataclasses.replace(real.result, distance_m=5.0, ntrt_distance_cm=500.0)
        _submit(core, "w1", (dataclasses.replace(real, result=bogus), honest))
        assert storage.columns()["verification"][0] == b"pending"
        assert core.search_done and not core.done  # the judge still has to run
        [judge] = _grant(core, "w2", 4).assignments  # the judge's task, leased like a trial
        assert judge.trial_id == 0 and judge.fidelity.task == "judge"
        assert judge.fidelity.dt_s == pytest.approx(0.001 / 4)  # the search's engine at a 4x finer step
        _submit(core, "w2", _run(evaluate, WorkGrant("r", "h", (judge,)), "w2"))
        cols = storage.columns()
        assert cols["verification"][0] == b"not_reproduced"
        assert 0.0 < cols["verify_distance_m"][0] < 1.0 and b"finer step" in cols["verify_reason"][0]
        [judge] = _grant(core, "w2", 4).assignments  # trial 1 is the best now: judged in turn
        assert judge.trial_id == 1
        _submit(core, "w2", _run(evaluate, WorkGrant("r", "h", (judge,)), "w2"))
        assert storage.columns()["verification"][1] == b"holds"
        assert storage.best_ids(2) == [1] and core.done  # the bogus trial never counts as best again
        assert storage.columns()["distance_m"][0] == 5.0  # both figures are stored
    finally:
        storage.close()
    reread = Hdf5Storage.open_read(tmp_path / "run.h5")
    assert [t.trial_id for t in reread.best(2)] == [1] and reread.trial(0).verification == "not_reproduced"


def test_test_objectives_and_disabled_policies_have_no_judge():
    core, _ = new_run(build_run_config("s", "sphere:3"), SearchSettings(trials=2), None, FakeClock())
    assert not core.tasks.judged or not core.study.storage.run_meta().settings.judge.enabled
    config = build_run_config("v", "tetraspine-ntrt", duration_s=0.1)
    core, storage = new_run(config, SearchSettings(trials=1, judge=JudgePolicy(enabled=False)), None, FakeClock())
    evaluate = build_evaluator(config)
    _submit(core, "w1", _run(evaluate, _grant(core, "w1", 1), "w1"))
    assert core.done and storage.columns()["verification"][0] == b""


def test_once_the_search_is_over_a_judge_of_an_overtaken_best_is_dropped(tmp_path):
    """The judge of an earlier best is still out on a worker when a better result arrives and the budget is
    done: the run stops waiting for it (its trial left unchecked, its late result stale) and judges the best."""
    config = build_run_config("overtaken", "tetraspine-ntrt", seed=3, duration_s=1.0)
    core, storage = new_run(config, SearchSettings(trials=2, startup_trials=2), tmp_path / "run.h5", FakeClock())
    evaluate = build_evaluator(config)
    try:
        first, better = sorted(_run(evaluate, _grant(core, "w1", 2), "w1"), key=lambda s: s.result.distance_m)
        _submit(core, "w1", (first,))
        [early_judge] = _grant(core, "w2", 1).assignments
        assert early_judge.trial_id == first.result.trial_id and early_judge.fidelity.task == "judge"
        _submit(core, "w1", (better,))
        assert core.search_done
        [judge] = _grant(core, "w1", 4).assignments
        assert judge.trial_id == better.result.trial_id
        late = _submit(core, "w2", _run(evaluate, WorkGrant("r", "h", (early_judge,)), "w2"))
        assert [v.value for _, v in late.verdicts] == ["stale"]
        _submit(core, "w1", _run(evaluate, WorkGrant("r", "h", (judge,)), "w1"))
        cols = storage.columns()
        assert cols["verification"][better.result.trial_id] == b"holds"
        assert cols["verification"][first.result.trial_id] == b""  # dropped, not judged
        assert core.done
    finally:
        storage.close()
