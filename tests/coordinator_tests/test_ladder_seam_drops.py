"""The Ladder on a real run file, in-process: which checks it stops and which it keeps. An overtaken best's
judge still queued is withdrawn, one already out is left to finish; once the search is over an overtaken best's
judge or opinion is stopped, and a check no live worker may run is dropped (an audit stays pending, said
unaudited; an opinion is dropped for good; the best's judge waits for a worker of its engine), but never within
the grace a restart gives its workers to reconnect (docs/distributed.md)."""

from __future__ import annotations

from spinefarm.coordinator.ladder.keys import AUDIT, JUDGE, OPINION, check_key
from spinefarm.coordinator.scheduler import START_GRACE_S
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.settings import AuditPolicy, JudgePolicy, Rung
from spinefarm.protocol.states import UNAUDITED
from tests.coordinator_tests.helpers import FakeClock, queued_keys
from tests.coordinator_tests.ladder_run import ENV_A, arrive, ladder_of, lease, outcome, run_check, run_file

BESTS = AuditPolicy(fraction=1e-9)    # auditing on, drawing almost nothing: the bests only
BULLET, MUJOCO, BOTH = ("bullet",), ("mujoco",), ("bullet", "mujoco")


def _live(ladder, **engines):
    """Workers that speak now, offering these engines."""
    for worker, offered in engines.items():
        ladder.peers.heard(worker, offered, ENV_A)
        ladder.leases.contact(worker)


def test_an_overtaken_bests_queued_judge_is_withdrawn_and_one_already_out_is_left_to_finish(tmp_path):
    storage = run_file(tmp_path / "r.h5", ((0.4, "w-a"),))
    ladder = ladder_of(storage)
    j0 = check_key(JUDGE, 0)
    assert queued_keys(ladder.leases) == [j0]
    arrive(ladder, 0.9, "w-a")        # a new best while trial 0's judge is still queued
    j1 = check_key(JUDGE, 1)
    assert queued_keys(ladder.leases) == [j1] and ladder.checks.pending == {j1}
    assert storage.columns()["verification"].tolist() == [b"", b"pending"]   # trial 0's undone
    out = lease(ladder, j1, "w-j")
    arrive(ladder, 2.0, "w-a")        # another, while trial 1's judge is out on w-j
    j2 = check_key(JUDGE, 2)
    assert ladder.checks.pending == {j1, j2} and queued_keys(ladder.leases) == [j2]
    assert ladder.leases.is_current(j1, out.lease_id, "w-j")
    assert storage.columns()["verification"].tolist() == [b"", b"pending", b"pending"]
    storage.close()


def test_an_overtaken_bests_opinion_is_withdrawn_even_while_a_worker_runs_it(tmp_path):
    judge = JudgePolicy(rung=Rung("bullet", 2.5e-4), share=1.0, opinion=Rung("mujoco", 1e-3))
    storage = run_file(tmp_path / "r.h5", ((0.4, "w-a"),), judge=judge)
    ladder = ladder_of(storage)
    run_check(ladder, check_key(JUDGE, 0), "w-j", outcome(0, 0.4, "w-j"))
    o0 = check_key(OPINION, 0)
    assert queued_keys(ladder.leases) == [o0]
    lease(ladder, o0, "w-o")
    arrive(ladder, 0.9, "w-a")
    # its late result finds no lease (stale); the new best's judge comes first
    assert ladder.leases.lease_of(o0) is None and o0 not in ladder.checks.pending
    assert queued_keys(ladder.leases) == [check_key(JUDGE, 1)]
    storage.close()


def test_within_the_restarts_grace_nothing_is_dropped_after_it_an_audit_is_said_unaudited_and_the_judge_waits(
        tmp_path):
    storage = run_file(tmp_path / "r.h5", ((0.4, "w-a"), (0.9, "w-a")), audit=BESTS, trials=2)
    clock = FakeClock()
    ladder = ladder_of(storage, clock)
    a1, j1 = check_key(AUDIT, 1), check_key(JUDGE, 1)
    assert ladder.study.done and ladder.checks.pending == {a1, j1}
    _live(ladder, **{"w-a": MUJOCO})                       # the row's own worker, not running Bullet
    clock.advance(START_GRACE_S - 0.5)                      # the workers may still be reconnecting
    ladder.drop_unservable()
    assert ladder.checks.pending == {a1, j1} and ladder.unaudited == {}
    clock.advance(1.0)
    _live(ladder, **{"w-a": MUJOCO})
    ladder.drop_unservable()
    # the audit: nobody else may run it, it stays pending in the file and is said so
    assert ladder.unaudited == {1: UNAUDITED} and storage.columns()["audit"].tolist() == [b"", b"pending"]
    # the best's judge waits for a worker with Bullet (the search is done once its best is judged)
    assert ladder.checks.pending == {j1} and not ladder.done
    assert storage.columns()["verification"][1] == b"pending" and queued_keys(ladder.leases) == [j1]
    _live(ladder, **{"w-b": BULLET})
    ladder.drop_unservable()
    assert ladder.checks.pending == {j1} and ladder.eligible(j1, "w-b")
    storage.close()


def test_once_the_search_is_over_an_overtaken_bests_judge_is_stopped_and_checks_a_worker_may_run_are_kept(tmp_path):
    storage = run_file(tmp_path / "r.h5", ((0.4, "w-a"), (0.9, "w-a")), audit=BESTS, trials=3)
    clock = FakeClock()
    ladder = ladder_of(storage, clock)
    j1 = check_key(JUDGE, 1)
    out = lease(ladder, j1, "w-j")                      # out on a worker: not withdrawn when overtaken
    arrive(ladder, 2.0, "w-b")
    assert ladder.study.done
    a1, a2, j2 = check_key(AUDIT, 1), check_key(AUDIT, 2), check_key(JUDGE, 2)
    assert ladder.checks.pending == {j1, a1, a2, j2}
    clock.advance(START_GRACE_S + 1.0)
    _live(ladder, **{"w-a": MUJOCO, "w-b": BOTH, "w-j": BULLET})
    ladder.drop_unservable()
    # trial 1 is no longer the best: its judge is stopped (w-j's result will be stale) and undone in the file
    assert ladder.checks.pending == {a1, a2, j2} and ladder.unaudited == {}
    assert not ladder.leases.is_current(j1, out.lease_id, "w-j")
    assert storage.columns()["verification"].tolist() == [b"", b"", b"pending"]
    assert storage.columns()["audit"].tolist() == [b"", b"pending", b"pending"]
    storage.close()


def test_an_opinion_no_live_worker_may_run_is_dropped_for_good_once_the_grace_is_over(tmp_path):
    judge = JudgePolicy(rung=Rung("bullet", 2.5e-4), share=1.0, opinion=Rung("mujoco", 1e-3))
    storage = run_file(tmp_path / "r.h5", ((0.4, "w-a"),), judge=judge, trials=1)
    clock = FakeClock()
    ladder = ladder_of(storage, clock)
    run_check(ladder, check_key(JUDGE, 0), "w-j", outcome(0, 0.4, "w-j"))
    o0 = check_key(OPINION, 0)
    assert ladder.checks.pending == {o0}
    _live(ladder, **{"w-j": BULLET})
    ladder.drop_unservable()
    assert ladder.checks.pending == {o0} and not ladder.done     # MuJoCo's worker may be reconnecting
    clock.advance(START_GRACE_S + 1.0)
    _live(ladder, **{"w-j": BULLET})
    ladder.drop_unservable()
    assert ladder.checks.pending == set() and ladder.checks.unservable == {o0} and ladder.done
    ladder.drop_unservable()                                   # not issued again
    assert ladder.checks.pending == set() and queued_keys(ladder.leases) == []
    storage.close()


def test_a_failed_result_changes_nothing_and_a_best_that_diverges_hands_the_audit_to_the_next(tmp_path):
    storage = run_file(tmp_path / "r.h5", ((0.4, "w-a"), (0.3, "w-b"), (0.9, "w-c")), audit=BESTS)
    storage.set_audit(2, "agrees", 0.9, "w-d")             # the best, audited already
    ladder = ladder_of(storage)
    j2 = check_key(JUDGE, 2)
    assert ladder.checks.pending == {j2}
    tid = storage.n_trials()
    storage.add_trial(tid, [0.5] * 3, [0.0] * 3, "monte_carlo", -1, 0)
    failed = TrialResult.failed("diverged: nan", 0, tid)
    assert ladder.study.tell(failed)
    ladder.after_trial(failed)
    assert ladder.checks.pending == {j2} and queued_keys(ladder.leases) == [j2]
    # the best diverges in the judge's run: it never counts, and trial 0, now the best, is audited and judged
    run_check(ladder, j2, "w-j", TrialResult.failed("diverged: nan", outcome(2, 0, "").seed, 2))
    assert storage.best_ids(1) == [0]
    assert sorted(queued_keys(ladder.leases)) == sorted([check_key(AUDIT, 0), check_key(JUDGE, 0)])
    storage.close()


def test_a_judge_no_live_worker_can_run_is_said_to_wait_once_not_dropped_at_every_request(tmp_path, caplog):
    storage = run_file(tmp_path / "r.h5", ((0.4, "w-a"), (0.9, "w-a")), trials=2)
    clock = FakeClock()
    ladder = ladder_of(storage, clock)
    j1 = check_key(JUDGE, 1)
    clock.advance(START_GRACE_S + 1.0)
    caplog.set_level("WARNING")
    for _ in range(3):                                      # three work requests from a MuJoCo-only worker
        _live(ladder, **{"w-a": MUJOCO})
        ladder.drop_unservable()
    assert j1 in ladder.checks.pending and queued_keys(ladder.leases) == [j1]
    said = [r.getMessage() for r in caplog.records if "judge of trial 1" in r.getMessage()]
    assert said == ["no live worker can run the judge of trial 1: it waits for one"]
    assert not any("dropped" in r.getMessage() for r in caplog.records)
    storage.close()
