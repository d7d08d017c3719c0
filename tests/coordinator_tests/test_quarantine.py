"""A quarantined worker's rows: every complete one is marked (it never counts as best) and re-run by another
identity as an audit, which settles it (the same result: agrees; another: disagrees); a restart keeps both the
quarantine and the re-runs still owed. In-process core, real HDF5 file."""

from __future__ import annotations

from spinefarm.coordinator.problem import build_run_config
from spinefarm.coordinator.setup import SearchSettings, new_run, resume_run
from spinefarm.protocol.settings import AuditPolicy
from tests.coordinator_tests.helpers import FakeClock
from tests.coordinator_tests.test_core import ask, res, submit


def test_a_quarantined_workers_rows_are_marked_re_run_elsewhere_and_kept_across_a_restart(tmp_path):
    out = tmp_path / "run.h5"
    config = build_run_config("q", "sphere:3", seed=3)
    core, storage = new_run(config, SearchSettings(trials=6, sampler="random", audit=AuditPolicy(fraction=0.01)),
                            out, FakeClock())
    theirs = {}
    grants = {w: ask(core, w, n=3).assignments for w in ("w1", "w2")}  # trials only: nothing is stored to audit
    for worker, distances in (("w1", (2.0, 2.1, 2.2)), ("w2", (1.0, 1.1, 1.2))):
        pairs = list(zip(grants[worker], distances, strict=True))
        items = [(a.lease_id, res(a, worker=worker, distance=d)) for a, d in pairs]
        assert set(submit(core, items, worker=worker).values()) == {"stored"}
        theirs[worker] = {a.trial_id: d for a, d in pairs}
    with core.lock:
        core.ladder.quarantine(core.peers.quarantine_identity("w1"), "found wrong")
    cols = storage.columns()
    assert [cols["audit"][t] for t in sorted(theirs["w1"])] == [b"quarantined"] * 3
    assert storage.best(1)[0].worker_id == "w2"  # none of w1's rows counts until another identity re-runs it
    storage.close()

    clock = FakeClock()
    core, storage = resume_run(out, clock)  # the quarantine and the owed re-runs are in the file
    # the first worker back after a restart is the quarantined one: the re-runs wait for the others
    assert core.peers.is_quarantined("w1") and ask(core, "w1", n=4).assignments == ()
    clock.advance(5.0)
    tasks = ask(core, "w2", n=8).assignments
    assert sorted(a.trial_id for a in tasks) == sorted(theirs["w1"]) and {a.fidelity.task for a in tasks} == {"audit"}
    rerun = {t: d if d < 2.2 else 1.5 for t, d in theirs["w1"].items()}  # two reproduce, the 2.2 m one does not
    assert set(submit(core, [(a.lease_id, res(a, worker="w2", distance=rerun[a.trial_id])) for a in tasks],
                      worker="w2").values()) == {"stored"}
    cols = storage.columns()
    by_distance = {theirs["w1"][t]: (cols["audit"][t], cols["audit_distance_m"][t]) for t in theirs["w1"]}
    assert by_distance == {2.0: (b"agrees", 2.0), 2.1: (b"agrees", 2.1), 2.2: (b"disagrees", 1.5)}
    best = storage.best(1)[0]  # a row cleared by its re-run counts again, also in a file opened after its marking
    assert (best.worker_id, best.distance_m, best.audit) == ("w1", 2.1, "agrees")
    # what is left is the audit of w2's best, which needs a third identity
    assert core.pending_check_kinds() == {"audit"} and not core.done
    storage.close()
