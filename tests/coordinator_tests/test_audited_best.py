"""With auditing on, a best needs an agreeing audit from another identity: a better set whose audit is still
pending is shown apart as "pending audit" in the progress line, the final report, `/runs`, `/runs/ID` and
`/runs/ID/best` (over HTTP), never as the best; once a resume with another identity runs its audit and agrees, it
is the best. In-process core, real HDF5 file and status file, the API served for real."""

from __future__ import annotations

from spinefarm.api.app import create_app
from spinefarm.cli.report import describe_best, progress
from spinefarm.coordinator.problem import build_run_config
from spinefarm.coordinator.setup import SearchSettings, new_run, resume_run
from spinefarm.protocol.settings import AuditPolicy
from spinefarm.storage.status import write_final_status
from tests.coordinator_tests.helpers import FakeClock
from tests.coordinator_tests.test_core import ask, res, submit
from tests.http_server import served

AUDITED_M, BETTER_M = 1.25, 3.5   # the audited best, and the better set no other identity has checked yet


def _api_views(directory, run_id):
    with served(create_app(runs_dir=directory)) as c:
        [listed] = c.get("/runs").json()
        return listed, c.get(f"/runs/{run_id}").json(), c.get(f"/runs/{run_id}/best", params={"k": 3}).json()


def test_a_set_whose_audit_is_pending_is_never_best_and_becomes_best_once_its_audit_agrees(tmp_path):
    out = tmp_path / "run.h5"
    config = build_run_config("audited", "sphere:3", seed=5)
    clock = FakeClock()
    # a fraction this small audits only the best (every new best is audited)
    core, storage = new_run(config, SearchSettings(trials=4, sampler="random", audit=AuditPolicy(fraction=0.001)),
                            out, clock)
    [first] = ask(core, "w1").assignments
    assert submit(core, [(first.lease_id, res(first, worker="w1", distance=AUDITED_M))]) == {first.trial_id: "stored"}
    [audit] = ask(core, "w2").assignments   # another identity audits the best and agrees
    assert audit.trial_id == first.trial_id and audit.fidelity.task == "audit"
    assert submit(core, [(audit.lease_id, res(audit, worker="w2", distance=AUDITED_M))], worker="w2") == {
        first.trial_id: "stored"}
    grant = ask(core, "w1", n=3)
    distances = (BETTER_M, 0.2, 0.3)   # the first is better than the audited best: its audit is issued
    items = [(a.lease_id, res(a, worker="w1", distance=d)) for a, d in zip(grant.assignments, distances, strict=True)]
    assert set(submit(core, items).values()) == {"stored"}
    better = grant.assignments[0].trial_id
    # the search ranks it first (its audit is due), the run reports the audited one
    assert storage.best_ids(1) == [better] and storage.columns()["audit"][better] == b"pending"
    assert [r.trial_id for r in storage.reported_best(2)[0]] == [first.trial_id]
    line = progress(core)[3]
    assert f"best {AUDITED_M:.3f} m ({BETTER_M:.3f} m pending audit)" in line

    # w2 is gone; only the better set's own identity is left: the run ends with its audit still pending
    core.worker_lost("w2")   # its liveliness token went away
    clock.advance(120.0)
    assert ask(core, "w1").run_done and core.done
    report = describe_best(core, out).splitlines()
    assert f"pending audit: trial {better}, distance {BETTER_M:g} m" in "\n".join(report)
    assert any(x.startswith(f"best trial {first.trial_id} ") for x in report)
    write_final_status(out, core.status())
    storage.close()
    listed, view, best = _api_views(tmp_path, config.run_id)
    for v in (listed, view):
        assert v["best"]["trial_id"] == first.trial_id and v["best_distance_m"] == AUDITED_M
        assert v["pending_audit"]["trial_id"] == better and v["pending_audit"]["audit"]["state"] == "pending"
    assert [b["trial_id"] for b in best] == [first.trial_id]   # only audited-and-agreeing sets are listed

    # resumed with another identity, its audit runs and agrees: now it is the best
    clock = FakeClock()
    core, storage = resume_run(out, clock)
    clock.advance(60.0)   # past the grace a restart gives its workers to come back
    [task] = ask(core, "w3").assignments
    assert task.trial_id == better and task.fidelity.task == "audit"
    assert submit(core, [(task.lease_id, res(task, worker="w3", distance=BETTER_M))], worker="w3") == {
        better: "stored"}
    assert [r.trial_id for r in storage.reported_best(2)[0]] == [better, first.trial_id]
    assert storage.reported_best(1)[1] is None
    assert "pending audit" not in progress(core)[3]
    write_final_status(out, core.status())
    storage.close()
    listed, view, best = _api_views(tmp_path, config.run_id)
    assert view["best"]["trial_id"] == better and view["best_distance_m"] == BETTER_M
    assert view["pending_audit"] is None
    assert [b["trial_id"] for b in best] == [better, first.trial_id]


def test_without_auditing_the_best_is_the_best_ranked_set(tmp_path):
    """Auditing off: nothing is withheld, nothing is pending."""
    out = tmp_path / "run.h5"
    core, storage = new_run(build_run_config("plain", "sphere:3", seed=5),
                            SearchSettings(trials=3, sampler="random"), out, FakeClock())
    grant = ask(core, "w1", n=3)
    items = [(a.lease_id, res(a, distance=d)) for a, d in zip(grant.assignments, (0.4, 2.0, 0.1), strict=True)]
    submit(core, items)
    ids, pending = storage.reported_best_ids(3)
    assert [storage.trial(i).distance_m for i in ids] == [2.0, 0.4, 0.1] and pending is None
    storage.close()
