"""An audit no other identity can run is not dropped silently: the run ends, the row's audit stays pending in the
file (a resume with another identity runs it), and the status, the report and the API say "unaudited (no other
worker identity)". In-process core, real HDF5 file and status file."""

from __future__ import annotations

from spinefarm.api.views import run_view
from spinefarm.cli.report import describe_best
from spinefarm.coordinator.problem import build_run_config
from spinefarm.coordinator.setup import SearchSettings, new_run, resume_run
from spinefarm.protocol.settings import AuditPolicy
from spinefarm.storage.hdf5 import Hdf5Storage
from spinefarm.storage.status import write_final_status
from tests.coordinator_tests.helpers import FakeClock
from tests.coordinator_tests.test_core import ask, res, submit

SAID = "unaudited (no other worker identity)"   # the words the task asks for


def test_a_best_no_other_identity_can_audit_stays_pending_and_is_said_unaudited(tmp_path):
    out = tmp_path / "run.h5"
    config = build_run_config("lone", "sphere:3", seed=3)
    # a fraction this small audits only the best, which is always audited
    clock = FakeClock()
    core, storage = new_run(config, SearchSettings(trials=3, sampler="random", audit=AuditPolicy(fraction=0.001)),
                            out, clock)
    grant = ask(core, "w1", n=3)
    distances = (2.5, 1.2, 0.7)   # every new best is audited: the first stays best, so it is the only one
    items = [(a.lease_id, res(a, worker="w1", distance=d)) for a, d in zip(grant.assignments, distances, strict=True)]
    assert set(submit(core, items, worker="w1").values()) == {"stored"}
    best = grant.assignments[0].trial_id
    assert storage.best(1)[0].trial_id == best and core.pending_check_kinds() == {"audit"}
    # the only worker is the result's own identity: once the start's grace for workers to come is over, the run
    # ends, and the audit is neither run nor dropped
    clock.advance(60.0)
    assert ask(core, "w1", n=1).run_done and core.done
    assert storage.columns()["audit"][best] == b"pending"
    assert core.status()["audit"]["unaudited"] == {str(best): SAID}
    assert SAID in describe_best(core, out)
    write_final_status(out, core.status())
    storage.close()

    with Hdf5Storage.open_read(out) as s:
        view = run_view(s, out)
    # no other identity agreed with it: it is not the best, it is shown apart as pending its audit
    assert view["best"] is None and view["pending_audit"]["trial_id"] == best
    assert view["pending_audit"]["audit"]["state"] == "pending"
    assert view["pending_audit"]["audit"]["note"] == SAID and view["audit"]["unaudited"] == {str(best): SAID}

    # resumed with another identity, the pending audit runs and settles
    clock = FakeClock()
    core, storage = resume_run(out, clock)
    clock.advance(60.0)   # past the grace a restart gives its workers to come back
    [task] = ask(core, "w2", n=2).assignments
    assert task.trial_id == best and task.fidelity.task == "audit"
    assert submit(core, [(task.lease_id, res(task, worker="w2", distance=2.5))], worker="w2") == {best: "stored"}
    assert storage.columns()["audit"][best] == b"agrees" and core.status()["audit"]["unaudited"] == {}
    storage.close()
