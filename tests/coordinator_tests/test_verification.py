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


def test_a_bogus_best_moved_at_the_finer_step_and_ranks_by_its_judged_distance(tmp_path):
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
        assert cols["verification"][0] == b"moved"
        judged_m = float(cols["verify_distance_m"][0])
        assert 0.0 < judged_m < 1.0 and cols["verify_reason"][0].startswith(b"moved ")
        if honest.result.distance_m > judged_m:  # trial 1's screen now leads the judged 5 m claim: judged in turn
            [judge] = _grant(core, "w2", 4).assignments
            assert judge.trial_id == 1
            _submit(core, "w2", _run(evaluate, WorkGrant("r", "h", (judge,)), "w2"))
            assert storage.columns()["verification"][1] == b"holds"
        assert core.done
        best = storage.best(2)
        # the 5 m claim never counts: the set ranks by what the finer step measured
        assert sorted([b.trial_id for b in best]) == [0, 1]
        figures = [b.verify_distance_m if b.verification else b.distance_m for b in best]
        assert figures == sorted(figures, reverse=True) and max(figures) < 1.0
        assert storage.columns()["distance_m"][0] == 5.0  # both figures are stored
        ranking = storage.best_ids(2)
    finally:
        storage.close()
    reread = Hdf5Storage.open_read(tmp_path / "run.h5")
    assert reread.best_ids(2) == ranking and reread.trial(0).verification == "moved"


def test_test_objectives_and_disabled_policies_have_no_judge():
    core, _ = new_run(build_run_config("s", "sphere:3"), SearchSettings(trials=2), None, FakeClock())
    assert not core.ladder.checks.judged or not core.study.storage.run_meta().settings.judge.enabled
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
        judged_m = cols["verify_distance_m"][better.result.trial_id]
        if judged_m >= first.result.distance_m:  # the judged best still leads: the early judge was dropped
            assert cols["verification"][first.result.trial_id] == b""  # dropped, not judged
            assert core.done
        else:  # the best is the best judged: the set it now trails is judged in turn before the run ends
            assert cols["verification"][first.result.trial_id] == b"pending" and not core.done
            [again] = _grant(core, "w2", 4).assignments
            assert again.trial_id == first.result.trial_id and again.fidelity.task == "judge"
            _submit(core, "w2", _run(evaluate, WorkGrant("r", "h", (again,)), "w2"))
            assert core.done
    finally:
        storage.close()
