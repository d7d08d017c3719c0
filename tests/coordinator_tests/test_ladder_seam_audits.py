"""The Ladder on a real run file, in-process: audits settled through the seam (what each was held to, counted
for the status; a disputed one's referee issued first; none for an agreeing one), a worker a referee
contradicts quarantined with everything it holds taken back and its rows re-run, its later results refused,
and a result carrying another row's seed refused with nothing stored (docs/distributed.md, "Audited results")."""

from __future__ import annotations

from spinefarm.coordinator.ladder.keys import AUDIT, JUDGE, REFEREE, check_key
from spinefarm.protocol.settings import AuditPolicy
from spinefarm.protocol.submissions import Verdict
from tests.coordinator_tests.helpers import queued_keys
from tests.coordinator_tests.ladder_run import (
    ENV_A,
    ENV_B,
    arrive,
    ladder_of,
    lease,
    outcome,
    run_check,
    run_file,
    store,
)

# exact within one environment, 5 % across environments
AUDITED = AuditPolicy(fraction=1e-9, tolerance=0.05)
ROWS = ((0.4, "w-a"), (0.9, "w-b"), (0.6, "w-c"), (0.3, "w-a"))


def _audited_run(path):
    """Rows 0-3; row 1 the best (audited as a best), rows 0 and 2 drawn for audits; workers' environments
    said: w-a, w-b and the auditor w-d in one, w-c in another."""
    storage = run_file(path, ROWS, audit=AUDITED)
    for tid in (0, 2):
        storage.set_audit(tid, "pending")      # issued again from the file, as after a restart
    ladder = ladder_of(storage)
    for worker, env in (("w-a", ENV_A), ("w-b", ENV_A), ("w-c", ENV_B), ("w-d", ENV_A), ("w-e", ENV_B)):
        ladder.peers.heard(worker, None, env)
        ladder.leases.contact(worker)
    return storage, ladder


def test_audits_count_what_they_were_held_to_and_only_a_disputed_one_queues_its_referee(tmp_path):
    storage, ladder = _audited_run(tmp_path / "r.h5")
    assert {check_key(AUDIT, t) for t in (0, 1, 2)} <= ladder.checks.pending
    assert ladder.audit_comparisons == {"exact": 0, "tolerance": 0}
    # w-b and w-d say the same environment: only the same bits agree
    assert run_check(ladder, check_key(AUDIT, 1), "w-d", outcome(1, 0.9, "w-d")) == Verdict.STORED
    assert ladder.audit_comparisons == {"exact": 1, "tolerance": 0}
    # w-c's environment is another: 3 % apart is within the 5 % tolerance
    run_check(ladder, check_key(AUDIT, 2), "w-d", outcome(2, 0.6 * 1.03, "w-d"))
    assert ladder.audit_comparisons == {"exact": 1, "tolerance": 1}
    assert storage.columns()["audit"][1:3].tolist() == [b"agrees", b"agrees"]
    assert not any(ladder.leases.queued(check_key(REFEREE, t)) for t in (1, 2))
    # one part in a million off in one environment: disputed, its referee issued before anything queued
    run_check(ladder, check_key(AUDIT, 0), "w-d", outcome(0, 0.4 * 1.000001, "w-d"))
    assert ladder.audit_comparisons == {"exact": 2, "tolerance": 1}
    referee = check_key(REFEREE, 0)
    assert storage.columns()["audit"][0] == b"disputed" and queued_keys(ladder.leases)[0] == referee
    # the referee (w-e, the other environment) agrees with the row: the audit was wrong
    assert not ladder.eligible(referee, "w-d") and ladder.eligible(referee, "w-e")
    run_check(ladder, referee, "w-e", outcome(0, 0.4 * 1.01, "w-e"))
    assert ladder.audit_comparisons == {"exact": 2, "tolerance": 2}
    assert storage.columns()["audit"][0] == b"overruled" and not ladder.leases.queued(referee)
    assert referee not in ladder.checks.pending
    storage.close()


def test_a_result_drawn_for_an_audit_is_audited_though_it_is_not_the_best(tmp_path):
    storage = run_file(tmp_path / "r.h5", ((0.9, "w-a"),), audit=AuditPolicy(fraction=1.0))   # every result
    ladder = ladder_of(storage)
    r = arrive(ladder, 0.2, "w-b")
    assert storage.best_ids(1) == [0] and check_key(AUDIT, r.trial_id) in ladder.checks.pending
    assert queued_keys(ladder.leases)[0] == check_key(AUDIT, r.trial_id)
    assert storage.columns()["audit"].tolist() == [b"pending", b"pending"]
    storage.close()


def test_a_worker_a_referee_contradicts_is_quarantined_its_leases_taken_back_and_its_rows_re_run(tmp_path):
    storage, ladder = _audited_run(tmp_path / "r.h5")
    waiting = store(storage, float("nan"), "").trial_id        # row 4, sampled: w-a will hold it
    ladder.leases.enqueue([waiting])
    run_check(ladder, check_key(AUDIT, 0), "w-d", outcome(0, 0.5, "w-d"))     # disputed: 0.5 m against 0.4 m
    held = lease(ladder, waiting, "w-a")
    assert ladder.leases.is_current(waiting, held.lease_id, "w-a")
    # the referee measures 0.5 m too: w-a's result is wrong, and w-a is quarantined (the audit policy's default)
    run_check(ladder, check_key(REFEREE, 0), "w-e", outcome(0, 0.5 * 1.01, "w-e"))
    assert ladder.peers.is_quarantined("w-a") and not ladder.peers.is_quarantined("w-d")
    # row 0 disagrees; w-a's other complete row (3) is marked and re-run by another worker first
    assert storage.columns()["audit"][[0, 3]].tolist() == [b"disagrees", b"quarantined"]
    a3 = check_key(AUDIT, 3)
    assert a3 in ladder.checks.pending and queued_keys(ladder.leases)[:2] == [a3, waiting]
    assert not ladder.leases.is_current(waiting, held.lease_id, "w-a")       # taken back from w-a
    assert not ladder.eligible(waiting, "w-a") and ladder.eligible(waiting, "w-b")
    # a result w-a sends now is refused, and the key goes to another worker first
    assert ladder.refuse_quarantined(waiting, "w-a") == Verdict.STALE
    assert queued_keys(ladder.leases)[0] == waiting
    assert ladder.refuse_quarantined(waiting, "w-b") is None
    storage.close()


def test_a_quarantine_of_a_worker_with_a_disputed_row_settles_it_and_withdraws_its_referee(tmp_path):
    storage, ladder = _audited_run(tmp_path / "r.h5")
    run_check(ladder, check_key(AUDIT, 2), "w-d", outcome(2, 0.9, "w-d"))     # w-c's row disputed
    referee = check_key(REFEREE, 2)
    assert ladder.leases.queued(referee)
    ladder.quarantine([], "nobody")
    assert ladder.leases.queued(referee) and storage.columns()["audit"][2] == b"disputed"
    ladder.quarantine(["w-c"], "its session's other worker was")
    # the disputing audit was its re-run: settled against w-c, nobody referees
    assert storage.columns()["audit"][2] == b"disagrees"
    assert not ladder.leases.queued(referee) and referee not in ladder.checks.pending
    storage.close()


def test_a_checks_result_with_another_seed_is_refused_and_stores_nothing(tmp_path):
    storage, ladder = _audited_run(tmp_path / "r.h5")
    judge = check_key(JUDGE, 1)
    held = lease(ladder, judge, "w-j")
    wrong = outcome(2, 0.8, "w-j")                              # row 2's seed, sent as row 1's
    assert ladder.settle_check(judge, "w-j", wrong) == Verdict.INVALID
    assert storage.columns()["verification"][1] == b"pending" and len(storage.evaluations()["kind"]) == 0
    assert judge in ladder.checks.pending and ladder.leases.is_current(judge, held.lease_id, "w-j")
    # a quarantined worker's result of a check is refused too
    ladder.peers.heard("w-j", None, ENV_A)
    assert ladder.peers.quarantine_identity("w-j") == ["w-j"]
    assert ladder.settle_check(judge, "w-j", outcome(1, 0.8, "w-j")) == Verdict.STALE
    assert storage.columns()["verification"][1] == b"pending" and queued_keys(ladder.leases)[0] == judge
    storage.close()
