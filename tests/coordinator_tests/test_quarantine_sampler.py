"""A quarantined worker's forged figures do not stay in a model-based sampler: once its worker is quarantined a
row's figure is not learnt (its re-run is owed), and once another identity's re-run comes back the sampler learns
that honest figure instead. TPE's own study is read: the values it holds for each parameter set. In-process
core, real HDF5 file."""

from __future__ import annotations

import math

from spinefarm.coordinator.problem import build_run_config
from spinefarm.coordinator.setup import SearchSettings, new_run
from spinefarm.protocol.settings import AuditPolicy
from tests.coordinator_tests.helpers import FakeClock
from tests.coordinator_tests.test_core import ask, res, submit

FORGED_M = (50.0, 60.0)     # far beyond what an honest worker measured
HONEST_M = (1.3, 1.4)       # what another identity's re-runs measure for the same two rows
W2_M = (1.0, 1.1)


def _learnt(core) -> dict[tuple[float, ...], float]:
    """What TPE learnt, by parameter set, after it proposes the next set (a new trial is asked for)."""
    study = core.study.sampler._study
    return {tuple(t.params[f"u{i}"] for i in range(len(t.params))): t.value for t in study.trials
            if t.value is not None}


def _row_params(storage, tid) -> tuple[float, ...]:
    return tuple(float(v) for v in storage.columns()["params_unit"][tid])


def test_a_quarantined_workers_forged_values_leave_the_sampler_and_its_re_runs_values_reach_it(tmp_path):
    out = tmp_path / "run.h5"
    config = build_run_config("qs", "sphere:3", seed=4)
    core, storage = new_run(config, SearchSettings(trials=12, sampler="tpe", audit=AuditPolicy(fraction=0.01)),
                            out, FakeClock())
    forged = ask(core, "w1", n=2).assignments
    honest = ask(core, "w2", n=2).assignments
    assert set(submit(core, [(a.lease_id, res(a, worker="w1", distance=d))
                             for a, d in zip(forged, FORGED_M, strict=True)]).values()) == {"stored"}
    assert set(submit(core, [(a.lease_id, res(a, worker="w2", distance=d))
                             for a, d in zip(honest, W2_M, strict=True)], worker="w2").values()) == {"stored"}
    # w3 takes the audits of both forged rows (each was best when stored) and a new set: TPE proposes it
    # having learnt the four rows as stored, the forged ones too
    reruns = [a for a in ask(core, "w3", n=3).assignments if a.fidelity.task == "audit"]
    assert sorted(a.trial_id for a in reruns) == sorted(a.trial_id for a in forged)
    learnt = _learnt(core)
    assert sorted(learnt.values()) == sorted((*FORGED_M, *W2_M))

    with core.lock:   # w1 is found wrong: its rows are marked, and w3's audits are now their re-runs
        core.ladder.quarantine(core.peers.quarantine_identity("w1"), "found wrong")
    assert ask(core, "w2", n=1).assignments[0].fidelity.task == "trial"   # a new set is proposed
    learnt = _learnt(core)   # the forged rows are being re-run: nothing of them is learnt
    assert all(_row_params(storage, a.trial_id) not in learnt for a in forged)
    assert sorted(learnt.values()) == sorted(W2_M)

    honest_of = {a.trial_id: d for a, d in zip(forged, HONEST_M, strict=True)}
    assert set(submit(core, [(a.lease_id, res(a, worker="w3", distance=honest_of[a.trial_id])) for a in reruns],
                      worker="w3").values()) == {"stored"}
    assert [storage.columns()["audit"][t] for t in sorted(honest_of)] == [b"disagrees"] * 2
    # a new set is proposed (beside the audit of w2's row, now the best)
    assert "trial" in {a.fidelity.task for a in ask(core, "w4", n=2).assignments}
    learnt = _learnt(core)   # the re-runs' figures, not the forged ones
    for tid, d in honest_of.items():
        assert math.isclose(learnt[_row_params(storage, tid)], d, rel_tol=0, abs_tol=0)
    assert not set(FORGED_M) & set(learnt.values())
    storage.close()
