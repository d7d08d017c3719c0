"""The Ladder (the seam the core asks) on a real run file, in-process: which worker may run which key, the
fidelity and assignment of a screen row, and the drift rule raising the screen's fidelity (docs/distributed.md,
"The judge watches the screen")."""

from __future__ import annotations

import logging
import math

import pytest

from spinefarm.coordinator.ladder.keys import AUDIT, JUDGE, REFEREE, check_key
from spinefarm.coordinator.study import trial_seed
from spinefarm.protocol.settings import AuditPolicy, TaskFidelity
from spinefarm.protocol.submissions import Verdict
from tests.coordinator_tests.helpers import FakeClock
from tests.coordinator_tests.ladder_run import (
    ENV_A,
    LEASE_S,
    SEED,
    arrive,
    ladder_of,
    outcome,
    run_check,
    run_file,
    store,
)

SCREEN = TaskFidelity("trial", None, None, None)      # the run's one rung: its engine and step, left to the worker
# docs/distributed.md: raised behind a judge in another engine, trials run in the judge's engine at 4x its step
RAISED = TaskFidelity("trial", "bullet", 4 * 2.5e-4, None)
BESTS = AuditPolicy(fraction=1e-9)    # auditing on, drawing almost nothing: the bests only


def test_a_worker_gets_keys_in_its_own_engines_only_and_none_once_quarantined(tmp_path):
    storage = run_file(tmp_path / "r.h5", ((0.4, "w-a"), (0.9, "w-b")))
    ladder = ladder_of(storage)
    for worker, engines in (("w-m", ("mujoco",)), ("w-b", ("bullet",)), ("w-any", None)):
        ladder.peers.heard(worker, engines, ENV_A)
    judge = check_key(JUDGE, 1)
    assert judge in ladder.checks.pending
    # a screen row runs in the run's engine (MuJoCo), the judge in Bullet; a worker that names none takes any
    assert [ladder.eligible(0, w) for w in ("w-m", "w-b", "w-any")] == [True, False, True]
    assert [ladder.eligible(judge, w) for w in ("w-m", "w-b", "w-any")] == [False, True, True]
    ladder.peers.quarantine_identity("w-any")
    assert not ladder.eligible(0, "w-any") and not ladder.eligible(judge, "w-any")
    storage.close()


def test_an_audit_goes_to_another_worker_and_a_referee_to_a_third(tmp_path):
    storage = run_file(tmp_path / "r.h5", ((0.4, "w-a"), (0.9, "w-b")), audit=BESTS)
    storage.set_audit(0, "disputed", 0.5, "w-c")
    ladder = ladder_of(storage)
    audit, referee = check_key(AUDIT, 1), check_key(REFEREE, 0)
    assert {audit, referee} <= ladder.checks.pending        # the best's audit, the disputed row's referee
    assert [ladder.eligible(audit, w) for w in ("w-a", "w-b", "w-c")] == [True, False, True]
    assert [ladder.eligible(referee, w) for w in ("w-a", "w-b", "w-c")] == [False, True, False]
    storage.close()


def test_with_identities_verified_an_audit_needs_a_known_single_identity_not_the_rows(tmp_path):
    storage = run_file(tmp_path / "r.h5", ((0.4, "w-a"), (0.9, "w-b")), audit=BESTS)
    ladder = ladder_of(storage, verify_identity=True)
    audit = check_key(AUDIT, 1)
    assert audit in ladder.checks.pending
    ladder.peers.identified("w-b", {"session-b"})
    assert not ladder.eligible(audit, "w-new")              # its identity is not known yet
    ladder.peers.identified("w-new", {"session-n"})
    ladder.peers.identified("w-twin", {"session-b"})        # another id in the row's worker's session
    ladder.peers.identified("w-both", {"session-x", "session-y"})
    assert [ladder.eligible(audit, w) for w in ("w-new", "w-twin", "w-both")] == [True, False, False]
    assert ladder.eligible(0, "w-twin")                     # a screen row goes to anybody
    storage.close()


def test_a_screen_rows_assignment_carries_its_set_seed_duration_and_the_time_left_on_its_lease(tmp_path):
    storage = run_file(tmp_path / "r.h5", ((0.4, "w-a"),))
    store(storage, math.nan, "", duration_s=2.5)            # rows 1 and 2: sampled, never finished
    store(storage, math.nan, "")
    clock = FakeClock()
    ladder = ladder_of(storage, clock)
    leases = ladder.leases.grant("w-m", 6, lambda: None, ladder.eligible)
    clock.advance(4.0)
    got = {lease.trial_id: ladder.assignment(lease, clock()) for lease in leases}
    assert {1, 2} <= set(got)
    # the i-th lease of a batch gets lease_s + i x the expected trial time (lease_s until one is measured,
    # docs/reliability.md); 4 s of it are gone when it is assigned
    assert [a.lease_s for a in got.values()] == [LEASE_S * (1 + i) - 4.0 for i in range(len(leases))]
    for t in (1, 2):
        a = got[t]
        assert a.trial_id == t and a.seed == trial_seed(SEED, t) and a.fidelity == SCREEN
        assert a.params_unit == pytest.approx((0.25 + 0.1 * t,) * 3)
    assert (got[1].duration_s, got[2].duration_s) == (2.5, None)   # none stored: the run's own
    storage.close()


def _judge_in_turn(ladder, ratios):
    """New bests in turn, each judged at screen / judge = its ratio (distances past the 10 cm floor)."""
    for ratio in ratios:
        distance_m = 2.0 ** ladder.study.storage.n_trials()   # each beats the last one's judged distance
        r = arrive(ladder, distance_m, "w-a")
        key = check_key(JUDGE, r.trial_id)
        assert run_check(ladder, key, "w-j", outcome(r.trial_id, distance_m / ratio, "w-j")) == Verdict.STORED


# the documented default band, [0.8, 1.2]; each window's median by hand
@pytest.mark.parametrize(("ratios", "raised"), [
    ((0.7, 0.75, 0.78), True),      # below: median 0.75
    ((0.85, 1.15, 0.9), False),     # inside: median 0.9
    ((0.7, 1.0, 1.35), False),      # one below, one above: median 1.0
    ((1.3, 1.25, 1.5), True),       # above: median 1.3
])
def test_three_judged_ratios_whose_median_leaves_the_band_raise_the_screens_fidelity(tmp_path, caplog, ratios,
                                                                                     raised):
    storage = run_file(tmp_path / "r.h5", ())
    assert storage.run_meta().settings.judge.drift == 0.2
    ladder = ladder_of(storage)
    store(storage, math.nan, "")                             # a screen row the search still has to run
    _judge_in_turn(ladder, ratios[:2])
    assert ladder.drift is None and ladder.fidelity(0) == SCREEN    # two ratios are no window
    with caplog.at_level(logging.WARNING, logger="spinefarm.coordinator"):
        _judge_in_turn(ladder, ratios[2:])
    assert (ladder.drift is not None, ladder.fidelity(0)) == (raised, RAISED if raised else SCREEN)
    said = [r for r in caplog.records if "no longer trusts the screen" in r.getMessage()]
    assert len(said) == int(raised)
    # a restarted coordinator reads the stored ratios: the fidelity stays as it was
    assert (ladder_of(storage).drift is not None) == raised
    storage.close()


def test_the_screen_is_said_untrusted_once_and_stays_raised_while_later_ratios_agree(tmp_path, caplog):
    storage = run_file(tmp_path / "r.h5", ())
    ladder = ladder_of(storage)
    with caplog.at_level(logging.WARNING, logger="spinefarm.coordinator"):
        _judge_in_turn(ladder, (1.3, 1.4, 1.5, 1.0, 1.0, 1.0))
    assert "1.4 of 3 judged bests outside [0.8, 1.2]" in ladder.drift   # the first window's median
    assert sum("no longer trusts the screen" in r.getMessage() for r in caplog.records) == 1
    assert ladder.fidelity(0) == RAISED
    storage.close()
