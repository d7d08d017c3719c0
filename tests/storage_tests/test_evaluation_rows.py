"""Every judge, audit and referee run is a row of its own (the evaluations table), linked to the row it checked,
kept through close, compression, resume and the API's reader; the judge's share of the workers' time is summed
from those rows on resume; and a run file of the older schema 7 (tests/storage_tests/data/run-schema7.h5, written
by spinefarm at d94d45a: five finished trials, one sampled, trial 1 "not_reproduced", trial 4 "holds" and audited)
still opens everywhere and says it is older."""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import h5py
import numpy as np

from spinefarm.api.app import create_app
from spinefarm.coordinator.ladder.checks import Checks
from spinefarm.protocol.states import AuditState
from spinefarm.storage.hdf5 import Hdf5Storage
from spinefarm.storage.hdf5_reader import Hdf5Reader
from spinefarm.storage.schema import FILE_SCHEMA_VERSION
from tests.http_server import served
from tests.storage_tests.conftest import make_meta, result

OLD = Path(__file__).parent / "data" / "run-schema7.h5"


def _run(path):
    s = Hdf5Storage.create(path, make_meta("run-e"))
    for tid, d in enumerate([0.5, 2.0, 1.0]):
        s.add_trial(tid, np.full(3, 0.5), np.zeros(3), "monte_carlo", -1, tid)
        s.finish_trial(tid, result(tid, d), d)
    return s, Checks(s, s.run_meta().settings, "bullet", 7, judged=True)


def _ran(trial_id, distance_m, wall_s, worker):
    return dataclasses.replace(result(trial_id, distance_m), wall_time_s=wall_s, worker_id=worker)


def test_judge_audit_and_referee_runs_are_rows_linked_to_the_row_they_checked(tmp_path):
    s, checks = _run(tmp_path / "e.h5")
    checks.settle_judge(1, _ran(1, 1.98, 3.0, "w-3"))
    checks.settle_audit(2, _ran(2, 1.3, 7.0, ""), "w-2", exact=False)   # 30 % off: disputed, refereed
    checks.settle_referee(2, _ran(2, 1.0, 11.0, "w-4"), exact=False)    # the referee sides with the result
    checks.settle_judge(2, _ran(2, 1.01, 5.0, "w-3"))
    s.close()
    expected = {"trial_id": [1, 2, 2, 2], "kind": [b"judge", b"audit", b"referee", b"judge"],
                "distance_m": [1.98, 1.3, 1.0, 1.01], "wall_time_s": [3.0, 7.0, 11.0, 5.0],
                "worker_id": [b"w-3", b"w-2", b"w-4", b"w-3"], "status": [b"complete"] * 4}
    with Hdf5Reader(tmp_path / "e.h5") as reader, Hdf5Storage.open_read(tmp_path / "e.h5") as snap:
        for rows in (reader.evaluations(), snap.evaluations()):
            assert {k: rows[k].tolist() for k in expected} == expected
        assert reader.trial(2).audit == AuditState.OVERRULED and reader.file_schema_version == FILE_SCHEMA_VERSION
    resumed = Hdf5Storage.resume(tmp_path / "e.h5")
    try:
        assert resumed.evaluations()["kind"].tolist() == expected["kind"]
        # the judge's share after a restart counts its two runs (3 s + 5 s), not the audit's or the referee's
        assert Checks(resumed, resumed.run_meta().settings, "bullet", 7, judged=True).judge_wall_s == 8.0
        checks = Checks(resumed, resumed.run_meta().settings, "bullet", 7, judged=True)
        checks.settle_judge(0, _ran(0, 0.5, 2.0, "w-3"))
    finally:
        resumed.close()
    with Hdf5Storage.open_read(tmp_path / "e.h5") as again:
        assert again.evaluations()["trial_id"].tolist() == [1, 2, 2, 2, 0]


def test_an_older_run_file_opens_everywhere_and_says_it_is_older(tmp_path):
    path = tmp_path / "old.h5"
    shutil.copy(OLD, path)
    with h5py.File(path, "r") as f:
        assert f.attrs["file_schema_version"] == 7 and "evaluations" not in f
    with Hdf5Storage.open_read(path) as old:
        assert old.file_schema_version == 7 and len(old.evaluations()["trial_id"]) == 0
        assert old.best_ids(3) == [4, 2, 0]   # trial 1 (2.0 m) was not reproduced: never best
    with Hdf5Reader(path) as reader:
        assert reader.file_schema_version == 7 and reader.best_ids(1) == [4]
    with served(create_app(runs_dir=tmp_path)) as c:
        st = c.get("/runs/run-v7").json()
        assert st["file_schema_version"] == 7 and "an older run file (schema 7" in st["file_note"]
        assert st["best"]["trial_id"] == 4 and st["best"]["verification"]["verdict"] == "holds"
        assert [b["trial_id"] for b in c.get("/runs/run-v7/best", params={"k": 2}).json()] == [4, 2]
    resumed = Hdf5Storage.resume(path)   # a resumed copy is written at the current version
    try:
        resumed.finish_trial(5, result(5, 0.75, seed=105), 0.75)
    finally:
        resumed.close()
    with h5py.File(path, "r") as f:
        assert f.attrs["file_schema_version"] == FILE_SCHEMA_VERSION and "evaluations" in f
    with Hdf5Reader(path) as reader:
        assert reader.file_schema_version == FILE_SCHEMA_VERSION and reader.trial(1).verification == "not_reproduced"
        assert reader.n_trials() == 6 and reader.best_ids(2) == [4, 2]
