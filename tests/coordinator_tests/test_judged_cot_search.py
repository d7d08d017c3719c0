"""A real search (local workers over Zenoh, the Tetraspine screened in MuJoCo, its bests judged in Bullet at
0.25 ms) stores the judge's cost of transport in the judge's evaluation row, and `/runs/ID/best` serves it: it
equals an independent `spinefarm trial` of the same parameters in the judge's engine at the judge's step, and it
is not the screen's."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from spinefarm.api.app import create_app
from spinefarm.protocol.states import EvaluationKind
from spinefarm.storage.evaluations import latest
from spinefarm.storage.hdf5 import Hdf5Storage
from tests.coordinator_tests.procs import ROOT
from tests.http_server import served

pytestmark = pytest.mark.integration
JUDGE_DT_S = 2.5e-4   # the judge's step: docs/distributed.md, Bullet's converged step


def _spinefarm(*args: str) -> str:
    r = subprocess.run([sys.executable, "-m", "spinefarm", *args], cwd=ROOT, capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    return r.stdout


def test_the_judged_best_cot_is_the_judges_run_and_not_the_screens(tmp_path):
    out = tmp_path / "run.h5"
    _spinefarm("search", "tetraspine-ntrt", "--engine", "mujoco", "--trials", "3", "--workers", "1",
               "--duration", "1", "--no-opinion", "--judge-share", "1", "--seed", "2", "--run-id", "cot",
               "--out", str(out), "--api-port", "-1", "--quiet")
    with Hdf5Storage.open_read(out) as s:
        [best] = s.reported_best(1)[0]
        row = latest(s.evaluations(), best.trial_id, EvaluationKind.JUDGE)
        stored = {k: v[row] for k, v in s.evaluations().items()}
    assert best.verification == "judged" and best.engine == "mujoco"
    assert (stored["engine"], stored["dt_s"], stored["status"]) == (b"bullet", JUDGE_DT_S, b"complete")
    with served(create_app(runs_dir=tmp_path)) as c:
        served_best = c.get("/runs/cot/best", params={"k": 1}).json()[0]
    assert served_best["trial_id"] == best.trial_id
    # the same parameters, seed and length, run apart from the search in Bullet at the judge's step
    alone = json.loads(_spinefarm("trial", "--run", str(out), "--trial-id", str(best.trial_id), "--engine", "bullet",
                                  "--dt", str(JUDGE_DT_S), "--json").strip().splitlines()[-1])
    assert alone["extras"]["engine"] == "bullet" and alone["extras"]["dt_s"] == JUDGE_DT_S
    assert served_best["judged_cot"] == stored["cot"] == alone["cot"]
    assert served_best["verification"]["judge_distance_m"] == alone["distance_m"]
    assert alone["cot"] != best.cot == served_best["scores"]["cot"]   # the screen's, in MuJoCo, differs
