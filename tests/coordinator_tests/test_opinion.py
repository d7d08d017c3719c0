"""A judged best's second opinion: run once in the other engine at that engine's converged step, stored as an
"opinion" evaluation row linked to the set's row, counted in the judge's share of time, never ranked, and due
from storage alone (a restarted coordinator issues it again)."""

from __future__ import annotations

import argparse
import dataclasses
import math

import numpy as np

from spinefarm.cli.run_setup import opinion_rung
from spinefarm.coordinator.problem import build_run_config
from spinefarm.coordinator.setup import SearchSettings, new_run, resume_run
from spinefarm.protocol.settings import JudgePolicy, Rung, RunSettings, TaskFidelity
from spinefarm.protocol.work import WorkGrant
from spinefarm.storage.ranking import evaluation_counts
from spinefarm.worker.service.zenoh_worker import build_evaluator
from tests.coordinator_tests.helpers import FakeClock
from tests.coordinator_tests.test_verification import _grant, _run, _submit

MUJOCO_CONVERGED_DT_S = 1e-3   # docs/accuracy.md: MuJoCo's 1 ms default, 0.46 % from its converged reference


def test_a_judged_best_gets_one_opinion_row_in_the_other_engine_issued_again_after_a_restart(tmp_path):
    config = build_run_config("opinion", "tetraspine-ntrt", seed=4, duration_s=1.0)
    judge = JudgePolicy(share=1.0, opinion=Rung("mujoco", MUJOCO_CONVERGED_DT_S))
    out = tmp_path / "run.h5"
    core, storage = new_run(config, SearchSettings(trials=3, startup_trials=3, judge=judge), out, FakeClock())
    evaluate = build_evaluator(config)
    try:
        _submit(core, "w1", _run(evaluate, _grant(core, "w1", 3), "w1"))
        [judged] = _grant(core, "w1", 4).assignments
        assert judged.fidelity.task == "judge" and judged.fidelity.engine is None   # the screen's engine, finer
        _submit(core, "w1", _run(evaluate, WorkGrant("r", "h", (judged,)), "w1"))
        best = storage.best_ids(1)[0]
        assert storage.columns()["verification"][best] in (b"holds", b"moved")
        [opinion] = _grant(core, "w2", 4).assignments
        assert opinion.trial_id == best and not core.done
        assert opinion.fidelity == TaskFidelity("opinion", "mujoco", MUJOCO_CONVERGED_DT_S)
        assert core.pending_check_kinds() == {"opinion"}
    finally:
        storage.close()   # the coordinator dies with the opinion out on a worker
    core, storage = resume_run(out, FakeClock())
    try:
        [again] = _grant(core, "w2", 4).assignments   # due from the stored rows alone
        assert (again.trial_id, again.fidelity) == (opinion.trial_id, opinion.fidelity)
        [item] = _run(evaluate, WorkGrant("r", "h", (again,)), "w2")
        _submit(core, "w2", (item,))
        assert core.done and _grant(core, "w2", 4).assignments == ()
        ev = storage.evaluations()
        assert ev["kind"].tolist() == [b"judge", b"opinion"]
        # the counts shown: every finished trial row, its judge's run and the opinion, one evaluation each
        rows = int(np.count_nonzero(storage.columns()["status"] == b"complete"))
        assert evaluation_counts(storage.columns(), ev)["evaluations_done"] == rows + 2
        row = {name: col[1] for name, col in ev.items()}
        assert (row["trial_id"], row["engine"], row["dt_s"], row["worker_id"], row["status"]) == (
            best, b"mujoco", MUJOCO_CONVERGED_DT_S, b"w2", b"complete")
        # the distance is MuJoCo's, measured apart from the coordinator, and not the judge's Bullet figure
        alone = evaluate(dataclasses.replace(again, fidelity=TaskFidelity("trial", "mujoco", MUJOCO_CONVERGED_DT_S)))
        assert row["distance_m"] == alone.distance_m != storage.columns()["verify_distance_m"][best]
        assert row["wall_time_s"] == item.result.wall_time_s > 0
        assert storage.best_ids(1) == [best] and storage.columns()["verify_distance_m"][best] != row["distance_m"]
    finally:
        storage.close()
    core, storage = resume_run(out, FakeClock())
    try:   # the judge's share, read back from the file, counts both of its kinds of run
        assert math.isclose(core.ladder.checks.judge_wall_s, float(np.sum(ev["wall_time_s"])))
        assert core.done and _grant(core, "w2", 4).assignments == ()   # no second opinion
    finally:
        storage.close()


def _args(**kw: object) -> argparse.Namespace:
    return argparse.Namespace(**{"opinion": None, "no_verify": False, **kw})


def test_the_opinion_runs_in_the_engine_the_judge_does_not_at_its_converged_step():
    assert opinion_rung(_args(), "bullet") == Rung("mujoco", 1e-3)   # both engines installed here: on
    assert opinion_rung(_args(), "mujoco") == Rung("bullet", 2.5e-4)
    assert opinion_rung(_args(opinion=False), "bullet") is None
    assert opinion_rung(_args(opinion=True, no_verify=True), "bullet") is None   # no judge, nothing judged
    stored = RunSettings(judge=JudgePolicy(opinion=Rung("mujoco", 1e-3)))
    assert RunSettings.from_dict(stored.to_dict()).judge.opinion == Rung("mujoco", 1e-3)
    assert RunSettings.from_dict({**stored.to_dict(), "judge": {"enabled": True}}).judge.opinion is None  # older


def test_an_opinion_without_an_engine_is_refused_in_one_line():
    import pytest

    from spinefarm.protocol.errors import ConfigError

    with pytest.raises(ConfigError, match="judge opinion is not a rung naming its engine"):
        JudgePolicy(opinion={"dt_s": 0.001})



def _ask(core, worker: str, engines: tuple[str, ...], n: int = 1) -> tuple:
    from spinefarm.protocol.envelope import decode_message
    from spinefarm.protocol.envelope import encode_message as enc
    from spinefarm.protocol.work import WorkRequest

    grant = decode_message(core.handle_work(enc(WorkRequest(worker, n, engines=engines))), WorkGrant)
    return grant.assignments


def _do(core, evaluate, worker: str, assignments: tuple) -> None:
    _submit(core, worker, _run(evaluate, WorkGrant("r", "h", assignments), worker))


def test_an_opinion_no_worker_can_run_is_dropped_so_the_run_ends_and_an_overtaken_bests_is_withdrawn():
    """Workers offering Bullet only: the judged best's MuJoCo opinion waits while workers may still be
    reconnecting, then is dropped, so the run ends; a better set, judged, takes the opinion over."""
    config = build_run_config("lone", "sphere:3", seed=2)
    judge = JudgePolicy(rung=Rung("bullet", 2.5e-4), share=1.0, opinion=Rung("mujoco", MUJOCO_CONVERGED_DT_S))
    clock = FakeClock()
    core, storage = new_run(config, SearchSettings(trials=3, startup_trials=3, judge=judge), None, clock)
    evaluate = build_evaluator(config)
    bullet, both = ("bullet",), ("bullet", "mujoco")
    _do(core, evaluate, "w1", _ask(core, "w1", bullet))            # trial 0: the best so far
    [judged] = _ask(core, "w1", bullet)
    assert judged.fidelity.task == "judge"
    _do(core, evaluate, "w1", (judged,))
    [opinion] = _ask(core, "w2", both)                             # out on w2, not yet back
    assert (opinion.trial_id, opinion.fidelity.task) == (0, "opinion")
    while not core.search_done:                                    # the other sets, and the judges they make due
        _do(core, evaluate, "w1", _ask(core, "w1", bullet))
    best = storage.best_ids(1)[0]
    assert best != 0 and storage.columns()["verification"][best] == b"judged"   # seed 2: a later set is better
    # trial 0's opinion was withdrawn: its late result is stale and stores nothing
    late = _submit(core, "w2", _run(evaluate, WorkGrant("r", "h", (opinion,)), "w2"))
    assert [v.value for _, v in late.verdicts] == ["stale"]
    assert core.pending_check_kinds() == {"opinion"}                  # the new best's, in MuJoCo
    core.worker_lost("w2")
    assert _ask(core, "w1", bullet) == () and not core.done         # not in Bullet; workers may still reconnect
    clock.advance(11.0)   # past the restart grace: no live worker runs MuJoCo
    _ask(core, "w1", bullet)
    assert core.done and core.pending_check_kinds() == set()
    assert b"opinion" not in storage.evaluations()["kind"].tolist()
