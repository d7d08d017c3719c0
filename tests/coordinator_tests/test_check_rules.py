"""The ladder's checks on storage alone, in-process: where an audit and its referee run (the row exactly as it
ran), who may not run them, when a judge is due (a run without a judge has none; the best only; not past the
judge's share while the search runs), and the judge's time starting from the stored rows."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from spinefarm.coordinator.ladder.checks import Checks
from spinefarm.coordinator.ladder.keys import AUDIT, JUDGE, OPINION, REFEREE, check_key
from spinefarm.protocol.settings import AuditPolicy, JudgePolicy, Rung, TaskFidelity
from spinefarm.protocol.states import TrialStatus
from spinefarm.storage.hdf5 import Hdf5Storage
from tests.storage_tests.conftest import make_meta, result

ROWS = (  # distance, engine, step, settle, worker
    (0.111, "mujoco", 0.002, 0.5, "w-a"),
    (0.213, "", math.nan, math.nan, "w-b"),
    (0.05, "bullet", 0.001, 1.0, "w-c"),
)


def _checks(path, judged=True, share=0.5, opinion=None, audit=0.0):
    meta = make_meta()
    settings = dataclasses.replace(meta.settings, judge=JudgePolicy(share=share, opinion=opinion),
                                   audit=AuditPolicy(fraction=audit))
    storage = Hdf5Storage.create(path, dataclasses.replace(meta, settings=settings))
    for tid, (d, engine, dt, settle, worker) in enumerate(ROWS):
        storage.add_trial(tid, np.full(3, 0.5), np.zeros(3), "monte_carlo", -1, tid)
        extras = {"engine": engine, "dt_s": dt, "settle_s": settle} if engine else {}
        storage.finish_trial(tid, dataclasses.replace(result(tid, d), worker_id=worker, extras=extras), d)
    return storage, Checks(storage, settings, "mujoco", 7, judged=judged)


def test_an_audit_and_its_referee_rerun_the_row_at_its_own_engine_step_and_settle(tmp_path):
    storage, checks = _checks(tmp_path / "r.h5")
    for kind in (AUDIT, REFEREE):
        assert checks.check_fidelity(check_key(kind, 0)) == TaskFidelity("audit", "mujoco", 0.002, 0.5)
        assert checks.check_fidelity(check_key(kind, 2)) == TaskFidelity("audit", "bullet", 0.001, 1.0)
        # a row that recorded no engine or step: the run's own, left to the worker
        assert checks.check_fidelity(check_key(kind, 1)) == TaskFidelity("audit", None, None, None)
    storage.close()


def test_an_opinion_without_an_opinion_rung_is_not_an_opinion(tmp_path):
    storage, checks = _checks(tmp_path / "r.h5", opinion=Rung("bullet", 2.5e-4))
    assert checks.check_fidelity(check_key(OPINION, 1)) == TaskFidelity("opinion", "bullet", 2.5e-4, None)
    assert checks.check_fidelity(check_key(AUDIT, 0)) == TaskFidelity("audit", "mujoco", 0.002, 0.5)   # not one
    storage.close()
    storage, checks = _checks(tmp_path / "s.h5")
    assert checks.check_fidelity(check_key(JUDGE, 1)).task == "judge"
    storage.close()


def test_an_audit_excludes_the_rows_worker_and_a_referee_the_audits_too(tmp_path):
    storage, checks = _checks(tmp_path / "r.h5")
    storage.set_audit(2, "disputed", 0.06, "w-d")
    assert checks.excluded(check_key(AUDIT, 2)) == {"w-c"}
    assert checks.excluded(check_key(REFEREE, 2)) == {"w-c", "w-d"}
    assert checks.excluded(check_key(JUDGE, 2)) == set()
    storage.close()


def test_a_judge_is_due_for_the_best_only_and_never_in_a_run_without_one(tmp_path):
    storage, checks = _checks(tmp_path / "r.h5", judged=False)
    assert checks.judge_due(0, search_over=True) == (None, [])
    storage.close()
    storage, checks = _checks(tmp_path / "s.h5", share=1.0)
    key, stale = checks.judge_due(0)
    assert key == check_key(JUDGE, 1) and stale == []          # the 0.213 m set, and only it
    assert storage.columns()["verification"].tolist() == [b"", b"pending", b""]
    storage.close()


def test_while_the_search_runs_a_judge_waits_for_its_share_and_at_the_end_it_does_not(tmp_path):
    storage, checks = _checks(tmp_path / "r.h5", share=0.25)
    # the trials took 3 x 0.25 s (conftest's wall time): a 0.25 share allows the judge 0.25 s (0.25 x 0.75 / 0.75)
    checks.judge_wall_s = 0.2
    assert checks.judge_due(0)[0] == check_key(JUDGE, 1)
    storage.set_verification(1, "")
    checks.judge_wall_s = 0.3
    assert checks.judge_due(0) == (None, [])
    assert checks.judge_due(0, search_over=True)[0] == check_key(JUDGE, 1)
    storage.close()


def test_the_judges_time_starts_at_zero_in_a_new_run(tmp_path):
    storage, checks = _checks(tmp_path / "r.h5")
    assert checks.judge_wall_s == 0.0
    storage.close()


def test_a_judge_exactly_at_its_share_may_still_run(tmp_path):
    storage, checks = _checks(tmp_path / "r.h5", share=0.25)
    checks.judge_wall_s = 0.25   # 0.25 x 0.75 = 0.25 x (3 x 0.25 s): at its share, not over it
    assert checks.over_share(storage.columns()["wall_time_s"]) is False
    storage.close()


def test_an_overtaken_bests_judge_is_named_stale_when_the_new_best_is_judged(tmp_path):
    storage, checks = _checks(tmp_path / "r.h5", share=1.0)
    old, _ = checks.judge_due(0)
    storage.add_trial(3, np.full(3, 0.5), np.zeros(3), "monte_carlo", -1, 3)
    storage.finish_trial(3, dataclasses.replace(result(3, 0.3), worker_id="w-a"), 0.3)
    checks.pending.add(check_key(AUDIT, 0))    # another kind of check pending: never stale here
    new, stale = checks.judge_due(0)
    assert (old, new, stale) == (check_key(JUDGE, 1), check_key(JUDGE, 3), [check_key(JUDGE, 1)])
    storage.close()


def test_a_dropped_judge_or_audit_is_undone_in_the_file_unless_it_is_kept_pending(tmp_path):
    storage, checks = _checks(tmp_path / "r.h5", share=1.0)
    key, _ = checks.judge_due(0)
    checks.drop(key)
    assert storage.columns()["verification"][1] == b"" and key not in checks.pending
    storage.set_audit(2, "pending")
    checks.drop(check_key(AUDIT, 2))
    assert storage.columns()["audit"][2] == b""
    storage.set_audit(2, "pending")
    checks.drop(check_key(AUDIT, 2), keep_pending=True)   # re-issued on resume, by another identity
    assert storage.columns()["audit"][2] == b"pending"
    storage.set_audit(2, "disputed", 0.06, "w-d")
    checks.drop(check_key(REFEREE, 2))                    # nobody to referee: the result stays disputed
    assert storage.columns()["audit"][2] == b"disputed"
    storage.close()


def test_while_the_search_runs_an_opinion_waits_for_the_judges_share(tmp_path):
    storage, checks = _checks(tmp_path / "r.h5", share=0.25, opinion=Rung("bullet", 2.5e-4))
    storage.set_verification(1, "judged", 0.2, "", 1.0)
    checks.judge_wall_s = 0.3
    assert checks.opinion_due() == (None, [])
    assert checks.opinion_due(search_over=True)[0] == check_key(OPINION, 1)
    storage.close()


def test_the_new_best_is_always_audited_and_other_results_only_when_drawn(tmp_path):
    storage, checks = _checks(tmp_path / "r.h5", audit=1e-9)   # auditing on, almost nothing drawn
    assert [checks.audit_due(t) for t in (0, 2)] == [None, None]
    assert checks.audit_due(1) == check_key(AUDIT, 1) and storage.columns()["audit"][1] == b"pending"
    storage.close()
    storage, checks = _checks(tmp_path / "s.h5")                # auditing off: not even the best
    assert checks.audit_due(1) is None and checks.best_audit_due() is None
    storage.close()


def test_a_best_without_an_audit_gets_one_once(tmp_path):
    storage, checks = _checks(tmp_path / "r.h5", audit=1e-9)
    assert checks.best_audit_due() == check_key(AUDIT, 1)
    assert storage.columns()["audit"].tolist() == [b"", b"pending", b""]
    assert checks.best_audit_due() is None          # pending already
    storage.set_audit(1, "agrees", 0.213, "w-d")
    assert checks.best_audit_due() is None          # audited
    storage.close()


def test_a_judges_run_stores_the_screen_to_judge_ratio_and_adds_its_time(tmp_path):
    storage, checks = _checks(tmp_path / "r.h5", share=1.0)
    judge = dataclasses.replace(result(1, 0.2), wall_time_s=0.75)
    checks.settle_judge(1, judge)
    checks.settle_judge(2, dataclasses.replace(result(2, 0.04), wall_time_s=0.5))
    cols = storage.columns()
    assert math.isclose(cols["judge_ratio"][1], 0.213 / 0.2) and math.isclose(cols["judge_ratio"][2], 0.05 / 0.04)
    checks.settle_judge(0, dataclasses.replace(result(0, 1.0), wall_time_s=0.0))    # a judged 1 m is a distance too
    assert math.isclose(storage.columns()["judge_ratio"][0], 0.111)
    assert checks.judge_wall_s == 1.25                              # 0.75 s + 0.5 s
    ev = storage.evaluations()
    assert ev["kind"].tolist() == [b"judge"] * 3
    storage.close()


def test_a_quarantined_workers_complete_rows_are_re_run_and_its_disputed_ones_settled_against_it(tmp_path):
    storage, checks = _checks(tmp_path / "r.h5")
    storage.add_trial(3, np.full(3, 0.5), np.zeros(3), "monte_carlo", -1, 3)   # w-a's, not finished: nothing
    storage.set_audit(0, "disputed", 0.09, "w-d")
    checks.pending.add(check_key(REFEREE, 0))
    reruns, settled = checks.mark_quarantined(["w-a"])
    # its only complete row was disputed: the disputing audit was its re-run, so nothing is run again
    assert (reruns, settled) == ([], [check_key(REFEREE, 0)])
    audit = storage.columns()["audit"].tolist()
    assert audit == [b"disagrees", b"", b"", b""]     # the disputed row settled against w-a; others untouched
    reruns, _ = checks.mark_quarantined(["w-b", "w-c"])
    assert sorted(reruns) == sorted([check_key(AUDIT, 1), check_key(AUDIT, 2)])
    assert storage.columns()["audit"].tolist() == [b"disagrees", b"quarantined", b"quarantined", b""]
    storage.close()


def _audited(path, tolerance=0.05):
    storage, checks = _checks(path, audit=1e-9)
    checks.settings = dataclasses.replace(checks.settings, audit=AuditPolicy(fraction=1e-9, tolerance=tolerance))
    return storage, checks


def test_an_exact_audit_agrees_only_to_the_bit_and_another_environments_within_the_tolerance(tmp_path):
    storage, checks = _audited(tmp_path / "r.h5")
    assert checks.settle_audit(1, result(1, 0.213), "w-d", exact=True) == [("w-b", True), ("w-d", True)]
    assert storage.columns()["audit"][1] == b"agrees"
    assert checks.settle_audit(0, result(0, 0.111 * 1.04), "w-d", exact=False) == [("w-a", True), ("w-d", True)]
    assert checks.settle_audit(2, result(2, 0.05 * 1.000001), "w-d", exact=True) == []   # one bit off: disputed
    assert storage.columns()["audit"][2] == b"disputed" and check_key(REFEREE, 2) in checks.pending
    assert storage.evaluations()["kind"].tolist() == [b"audit"] * 3
    storage.close()


def test_an_audit_outside_the_tolerance_is_disputed_and_a_quarantined_rows_re_run_disagrees_outright(tmp_path):
    storage, checks = _audited(tmp_path / "r.h5")
    assert checks.settle_audit(0, result(0, 0.111 * 1.06), "w-d", exact=False) == []
    assert storage.columns()["audit"][0] == b"disputed"
    storage.set_audit(1, "quarantined")              # a quarantined worker's re-run: no referee, it disagrees
    assert checks.settle_audit(1, result(1, 0.3), "w-d", exact=True) == []
    assert storage.columns()["audit"][1] == b"disagrees" and check_key(REFEREE, 1) not in checks.pending
    storage.close()


def test_a_referee_agreeing_with_the_result_overrules_the_audit_else_the_result_is_wrong(tmp_path):
    storage, checks = _audited(tmp_path / "r.h5")
    checks.settle_audit(0, result(0, 0.2), "w-d", exact=True)
    checks.settle_audit(2, result(2, 0.2), "w-d", exact=True)
    assert checks.settle_referee(0, result(0, 0.111), exact=True) == [("w-d", False), ("w-a", True)]
    assert checks.settle_referee(2, result(2, 0.07), exact=True) == [("w-c", False)]
    cols = storage.columns()
    assert (cols["audit"][0], cols["audit"][2]) == (b"overruled", b"disagrees")
    assert storage.evaluations()["kind"].tolist() == [b"audit", b"audit", b"referee", b"referee"]
    storage.close()


def test_a_failed_judge_run_has_no_ratio_and_an_opinion_adds_its_time(tmp_path):
    storage, checks = _checks(tmp_path / "r.h5", share=1.0)
    checks.settle_judge(1, result(1, 0.3, status=TrialStatus.FAILED, reason="diverged: nan"))
    assert math.isnan(storage.columns()["judge_ratio"][1])      # never a drift figure
    before = checks.judge_wall_s
    checks.settle_opinion(2, dataclasses.replace(result(2, 0.04), wall_time_s=0.5))
    checks.settle_opinion(0, dataclasses.replace(result(0, 0.1), wall_time_s=0.25))
    assert checks.judge_wall_s == before + 0.75
    storage.close()


def test_only_this_sets_own_judge_timeouts_count_towards_its_retries(tmp_path):
    storage, checks = _checks(tmp_path / "r.h5", share=1.0)
    timeout = result(0, 0.0, status=TrialStatus.FAILED, reason="timeout: no result within its 55.8 s limit")
    checks.settle_judge(0, timeout)                                  # another set's timeout
    checks.settle_judge(1, result(1, 0.0, status=TrialStatus.FAILED, reason="crashed: the trial process died"))
    storage.set_verification(1, "")
    for _ in range(2):
        checks.settle_judge(1, dataclasses.replace(timeout, trial_id=1))
        assert storage.columns()["verification"][1] == b""            # issued again
    storage.close()
