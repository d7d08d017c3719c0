"""What a user is shown as best is what the highest fidelity measured, and sets and evaluations are counted
apart: a multi-fidelity run file asked for 12 sets (12 first-rung rows, 4 promoted, one judge run, one audit)
shows 12 sets and 18 evaluations; its best moved 5.2 % at the finer step (0.213 m screened, 0.202 m judged)
and stays best with 0.202 m in `/runs`, `/runs/ID/best`, `/runs/ID` and the final report."""

from __future__ import annotations

import numpy as np

from spinefarm.api.app import create_app
from spinefarm.cli.report import final_report, verdict_text
from spinefarm.protocol.states import AuditState, Verification
from spinefarm.storage.hdf5 import Hdf5Storage
from tests.http_server import served
from tests.storage_tests.conftest import make_meta, result

SCREEN_M = [0.05, 0.111, 0.02, 0.213, 0.03, 0.04, 0.06, 0.07, 0.08, 0.09, 0.01, 0.015]
PROMOTED = [3, 1, 9, 8]        # the best quarter goes on to the full length (rung 1)
FULL_M = [0.213, 0.111, 0.09, 0.08]


def _multi_fidelity_run(path):
    s = Hdf5Storage.create(path, make_meta("run-m", budget=12))
    for tid, d in enumerate(SCREEN_M):
        s.add_trial(tid, np.full(3, 0.5), np.zeros(3), "monte_carlo", -1, tid)
        s.finish_trial(tid, result(tid, d), d)
    for k, (parent, d) in enumerate(zip(PROMOTED, FULL_M, strict=True)):
        tid = len(SCREEN_M) + k
        s.add_trial(tid, np.full(3, 0.5), np.zeros(3), "promoted", parent, tid, rung=1)
        s.finish_trial(tid, result(tid, d), d)
    s.set_verification(12, Verification.MOVED, 0.202, "moved 5.2% at the finer step (0.213 m -> 0.202 m; floor 1.0%)",
                       0.213 / 0.202)
    s.set_audit(13, AuditState.AGREES, 0.111, "w-2")
    s.close()


def test_a_moved_best_is_shown_with_its_judged_distance_and_sets_apart_from_evaluations(tmp_path):
    _multi_fidelity_run(tmp_path / "m.h5")
    with served(create_app(runs_dir=tmp_path)) as c:
        [listed] = c.get("/runs").json()
        st = c.get("/runs/run-m").json()
        best = c.get("/runs/run-m/best", params={"k": 2}).json()
    for view in (listed, st):
        assert (view["parameter_sets_done"], view["evaluations_done"], view["trials_budget"]) == (12, 18, 12)
        assert view["best_distance_m"] == 0.202 and view["best"]["trial_id"] == 12
    assert [b["trial_id"] for b in best] == [12, 13]
    v = best[0]["verification"]
    assert (v["verdict"], v["label"], v["counted_distance_m"]) == ("moved", "moved 5.2% at the finer step", 0.202)


def test_the_final_report_counts_sets_and_evaluations_and_gives_the_judged_distance(tmp_path):
    _multi_fidelity_run(tmp_path / "m.h5")
    with Hdf5Storage.open_read(tmp_path / "m.h5") as s:
        b = s.best(1)[0]
        verdict = verdict_text(b, None)
        text = final_report(s, tmp_path / "m.h5", verdict=verdict, done=True)
    lines = text.splitlines()
    assert lines[0].startswith("search done: 12 parameter sets, 18 evaluations of sphere:3 (0 failed)")
    assert lines[1].startswith("best trial 12 ")
    assert "distance 0.202 m (judged)" in lines[2]
    assert verdict == "moved 5.2% at the finer step: 0.202 m judged (the distance that counts; screen 0.213 m)"
