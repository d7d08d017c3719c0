"""Pareto front of speed (max) and COT (min): marked in storage as results arrive, served and exported."""

from __future__ import annotations

import io
import math
import subprocess
import sys

import numpy as np
import pytest

from spinefarm.api.app import create_app
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.states import TrialStatus
from spinefarm.storage import pareto
from spinefarm.storage.export import write_csv
from spinefarm.storage.hdf5 import Hdf5Storage
from tests.coordinator_tests.procs import ROOT
from tests.http_server import served

# (speed cm/s, COT, status); the front is known by construction
SYNTHETIC = [
    (1.0, 1.0, "complete"),    # 0 front: cheapest
    (2.0, 2.0, "complete"),    # 1 front
    (3.0, 4.0, "complete"),    # 2 front
    (4.0, 8.0, "complete"),    # 3 front: fastest complete
    (1.0, 2.0, "complete"),    # 4 dominated by 0 (same speed, dearer)
    (2.0, 3.0, "complete"),    # 5 dominated by 1
    (2.5, 4.0, "complete"),    # 6 dominated by 2 (slower, same cost)
    (0.5, 1.5, "complete"),    # 7 dominated by 0
    (2.0, 2.0, "complete"),    # 8 front: equal to 1, neither dominates
    (9.0, 0.5, "failed"),      # 9 not a candidate: failed trials never count
    (0.0, math.inf, "complete"),  # 10 no motion: dominated
    (3.5, 7.9, "complete"),    # 11 front: between 2 and 3
]
FRONT = {0, 1, 2, 3, 8, 11}


def _result(tid: int, speed: float, cot: float, status: str) -> TrialResult:
    st = TrialStatus.COMPLETE if status == "complete" else TrialStatus.FAILED
    return TrialResult(st, "" if st == TrialStatus.COMPLETE else "diverged: test", speed / 100 * 10, speed * 10,
                       speed, 1.0, cot, 1.5, 10.0, 0.1, tid, trial_id=tid, worker_id="w")


def fill(storage, order):
    for i in range(len(SYNTHETIC)):
        storage.add_trial(i, np.full(3, 0.5), np.zeros(3), "monte_carlo", -1, i)
    for i in order:
        speed, cot, status = SYNTHETIC[i]
        storage.finish_trial(i, _result(i, speed, cot, status), speed)


def test_batch_front_of_a_synthetic_set():
    speed = np.array([s for s, _, _ in SYNTHETIC])
    cot = np.array([c for _, c, _ in SYNTHETIC])
    status = np.array([st.encode() for _, _, st in SYNTHETIC])
    assert set(np.flatnonzero(pareto.front_mask(status, speed, cot))) == FRONT


@pytest.mark.parametrize("seed", range(4))
def test_storage_marks_the_front_whatever_order_results_arrive_in(storage, seed):
    order = np.random.default_rng(seed).permutation(len(SYNTHETIC))
    # the fixture's run has 3 parameters; the table holds what it is given
    fill(storage, order)
    cols = storage.columns()
    assert set(np.flatnonzero(cols["pareto_front"] == 1)) == FRONT
    assert storage.pareto_ids() == [3, 11, 2, 1, 8, 0]  # fastest first, ties by id
    assert storage.trial(11).pareto_front == 1 and storage.trial(4).pareto_front == 0


def test_random_sets_agree_with_the_batch_front(storage):
    rng = np.random.default_rng(3)
    n = 300
    speed = np.round(rng.random(n) * 5, 1)  # rounded: ties happen
    cot = np.round(rng.random(n) * 10, 1)
    for i in range(n):
        storage.add_trial(i, np.full(3, 0.5), np.zeros(3), "monte_carlo", -1, i)
    for i in rng.permutation(n):
        storage.finish_trial(int(i), _result(int(i), speed[i], cot[i], "complete"), speed[i])
    cols = storage.columns()
    expected = pareto.front_mask(cols["status"], speed, cot)
    brute = [not any(pareto.dominates(speed[j], cot[j], speed[i], cot[i]) for j in range(n)) for i in range(n)]
    assert np.array_equal(expected, brute)
    assert np.array_equal(cols["pareto_front"] == 1, expected)


def test_the_file_marks_the_front_and_the_api_and_export_serve_it(tmp_path):
    from tests.storage_tests.conftest import make_meta

    path = tmp_path / "run.h5"
    s = Hdf5Storage.create(path, make_meta("run-p"))
    fill(s, range(len(SYNTHETIC)))
    s.close()
    again = Hdf5Storage.open_read(path)
    assert set(np.flatnonzero(again.columns()["pareto_front"] == 1)) == FRONT
    with served(create_app([path])) as c:
        body = c.get("/runs/run-p/pareto").json()
    assert [t["trial_id"] for t in body] == [3, 11, 2, 1, 8, 0]
    assert body[0]["scores"]["speed_cm_s"] == 4.0 and body[0]["scores"]["cot"] == 8.0
    assert all(t["pareto_front"] for t in body)
    buf = io.StringIO()
    write_csv(again, buf)
    header = buf.getvalue().splitlines()[0].split(",")
    assert "pareto_front" in header
    out = tmp_path / "front.csv"
    r = subprocess.run([sys.executable, "-m", "spinefarm", "export", str(path), "--pareto", str(out)], cwd=ROOT,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    rows = out.read_text().splitlines()
    assert len(rows) == 1 + len(FRONT) and [int(x.split(",")[0]) for x in rows[1:]] == [3, 11, 2, 1, 8, 0]
