"""The fidelity ladder with real processes over Zenoh: the coordinator loads no simulator (the judge is a
worker's task), tasks go only to workers that run their engine, and audits find a worker that disagrees."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import numpy as np

from spinefarm.storage.hdf5 import Hdf5Storage
from spinefarm.storage.status import read_status
from tests.coordinator_tests.helpers import free_endpoint
from tests.coordinator_tests.procs import ROOT, coordinator, stop

SIMULATORS = {"pybullet", "mujoco", "numba"}


def _worker(endpoint: str, run_id: str, worker_id: str, *extra: str, env: dict | None = None) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "spinefarm", "worker", "--connect", endpoint, "--run", run_id,
                             "--worker-id", worker_id, "--batch", "1", "--exit-when-done", *extra], cwd=ROOT,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env={**os.environ, **(env or {})})


def test_a_search_judges_its_best_on_a_worker_and_its_coordinator_loads_no_simulator(tmp_path):
    out = tmp_path / "run.h5"
    code = ("import json, sys\nfrom spinefarm.cli.main import main\n"
            f"rc = main(['search', 'tetraspine-ntrt', '--trials', '6', '--duration', '0.3', '--workers', '1', "
            # --engine auto (the default) calibrates first, a small calibration: it must not load a simulator here
            f"'--calibrate-gaits', '4', '--calibrate-search-trials', '2', '--calibrate-bests', '2', "
            f"'--calibrate-duration', '0.5', '--calibrate-settle', '0.2', "
            f"'--api-port', '-1', '--quiet', '--out', {str(out)!r}])\n"
            "print(json.dumps({'rc': rc, 'loaded': sorted({m.split('.')[0] for m in sys.modules})}))\n")
    r = subprocess.run([sys.executable, "-P", "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    report = json.loads(r.stdout.strip().splitlines()[-1])
    assert report["rc"] == 0, r.stderr[-2000:]
    assert not set(report["loaded"]) & SIMULATORS  # the judge ran in the worker's process, not here
    with Hdf5Storage.open_read(out) as s:
        best = s.best(1)[0]
        # a Bullet search's best is re-simulated at a 4x finer step; a MuJoCo screen's is judged in Bullet
        assert best.verification in ("holds", "judged") and np.isfinite(best.verify_distance_m)
        assert best.verify_distance_m != best.distance_m


def test_tasks_go_only_to_workers_that_run_their_engine(tmp_path):
    """A MuJoCo screen judged in Bullet, served by a worker that runs only MuJoCo and one that runs only
    Bullet: every screening trial goes to the first, the judge to the second."""
    ep, out = free_endpoint(), tmp_path / "run.h5"
    coord = coordinator(ep, out, "sphere:3", "--trials", "12", "--engine", "mujoco", "--verify-engine", "bullet",
                        "--duration", "0.01", "--run-id", "eng")
    workers = [_worker(ep, "eng", "only-mujoco", "--engines", "mujoco"),
               _worker(ep, "eng", "only-bullet", "--engines", "bullet")]
    try:
        assert coord.wait(90) == 0
        with Hdf5Storage.open_read(out) as s:
            cols = s.columns()
            assert set(cols["worker_id"].tolist()) == {b"only-mujoco"}
            best = s.best(1)[0]
            assert best.verification == "judged" and best.judge_ratio == 1.0  # the test objective has no engine
        status = read_status(out)
        engines = {w["worker_id"]: w["engines"] for w in status["workers"]}
        assert engines == {"only-mujoco": ["mujoco"], "only-bullet": ["bullet"]}
    finally:
        stop(coord, *workers)


def test_an_audit_finds_the_worker_that_disagrees_and_quarantines_it(tmp_path):
    """Three honest workers and one whose distances are 1.5x what it measured: its audited results are
    disputed, a third worker referees, and it is marked and gets no more work; its inflated results never
    count as best. /runs shows the audit figures and each worker's environment."""
    ep, out = free_endpoint(), tmp_path / "run.h5"
    # the workers wait for their coordinator: all four are there from the first trial on
    workers = [_worker(ep, "aud", "bad", env={"SPINEFARM_FAULT_DISTANCE_SCALE": "1.5"})]
    workers += [_worker(ep, "aud", f"honest{i}") for i in range(3)]
    time.sleep(3.0)
    coord = coordinator(ep, out, "sphere:3", "--trials", "100", "--audit", "0.25", "--duration", "0.05",
                        "--run-id", "aud")
    try:
        assert coord.wait(120) == 0
        with Hdf5Storage.open_read(out) as s:
            cols = s.columns()
            best = s.best(1)[0]
        audit, wid, auditor = cols["audit"], cols["worker_id"], cols["audit_worker_id"]
        # the bad worker is caught either way: its results refereed against it, or its audits overruled
        assert (audit == b"disagrees").any() or (audit == b"overruled").any()
        assert set(wid[audit == b"disagrees"].tolist()) <= {b"bad"}  # only the bad worker's results are blamed
        assert set(auditor[audit == b"overruled"].tolist()) <= {b"bad"}  # and only its audits are overruled
        assert (audit == b"agrees").sum() > 0 and best.worker_id != "bad"
        status = read_status(out)
        quarantined = {w["worker_id"]: w["quarantined"] for w in status["workers"]}
        assert quarantined == {"honest0": False, "honest1": False, "honest2": False, "bad": True}
    finally:
        stop(coord, *workers)
    from spinefarm.api.app import create_app
    from tests.http_server import served

    with served(create_app(runs_dir=tmp_path)) as client:
        run = client.get("/runs/aud").json()
    assert run["audit"]["audits_disagrees"] == int((audit == b"disagrees").sum()) and run["audit"]["fraction"] == 0.25
    assert run["audit"]["audits_overruled"] == int((audit == b"overruled").sum())
    [bad] = [e for e in run["audit"]["environments"] if "bad" in e["workers"]]
    assert bad["audits_disagree"] >= 1  # the environment it reported is marked too
    assert {w["worker_id"] for w in run["workers"] if w["quarantined"]} == {"bad"}
    assert all(w["environment"]["python"] for w in run["workers"])
