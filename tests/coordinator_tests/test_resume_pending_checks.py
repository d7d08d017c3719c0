"""kill -9 of a coordinator with a pending judge, pending audits AND pending referees, then `--resume`: every one
is issued again (an evaluation row of its kind, run after the kill) and the run ends at exactly its budget. Real
processes, Zenoh over TCP, a real run file.

How each stays pending before the kill: the screen runs in MuJoCo (the test objective routes by it), the judge
in Bullet, and the first workers offer only MuJoCo;
the first worker's results are audited by the second, which inflates every distance by 4.9 % (the same code
and environment: only the same bits agree), so each audit is disputed and its referee needs a third identity;
the second worker's own results wait for an audit by another identity once the first has gone."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import numpy as np
import pytest

from spinefarm.storage.hdf5 import Hdf5Storage
from spinefarm.storage.hdf5_reader import read_run
from tests.coordinator_tests.helpers import free_endpoint
from tests.coordinator_tests.procs import ROOT, coordinator, stop, wait_status, worker

pytestmark = pytest.mark.integration


def _worker(endpoint: str, run_id: str, worker_id: str, *extra: str, env: dict | None = None) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "spinefarm", "worker", "--connect", endpoint, "--run", run_id,
                             "--worker-id", worker_id, "--batch", "1", "--exit-when-done", *extra], cwd=ROOT,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env={**os.environ, **(env or {})})


def _all_three(st: dict) -> bool:
    pending = st.get("checks_pending", {})
    return all(pending.get(k, 0) >= 1 for k in ("judge", "audit", "referee"))


def test_pending_judges_audits_and_referees_are_issued_again_after_a_kill(tmp_path):
    ep, out = free_endpoint(), tmp_path / "run.h5"
    budget = 120
    coord = coordinator(ep, out, "sphere:4", "--trials", str(budget), "--duration", "0.04", "--run-id", "pc",
                        "--audit", "1", "--engine", "mujoco", "--judge-share", "1")
    first = _worker(ep, "pc", "w1", "--engines", "mujoco")
    procs = [coord, first]
    try:
        wait_status(out, lambda st: st["trials_complete"] >= 6 and st.get("checks_pending", {}).get("audit", 0) >= 3
                    and st.get("checks_pending", {}).get("judge", 0) >= 1, "6 trials, 3 audits and a judge pending")
        first.send_signal(signal.SIGKILL)
        first.wait(10)
        liar = _worker(ep, "pc", "w2", "--engines", "mujoco", env={"SPINEFARM_FAULT_DISTANCE_SCALE": "1.049"})
        procs.append(liar)
        wait_status(out, _all_three, "a judge, an audit and a referee pending", timeout_s=90)
        coord.send_signal(signal.SIGKILL)
        coord.wait(10)
        liar.kill()
        liar.wait(10)
        _, before = read_run(out)
        with Hdf5Storage.open_read(out) as s:
            n_rows_before = len(s.evaluations()["trial_id"])
        judges = np.flatnonzero(before["verification"] == b"pending")
        audits = np.flatnonzero(before["audit"] == b"pending")
        referees = np.flatnonzero(before["audit"] == b"disputed")
        assert judges.size >= 1 and audits.size >= 1 and referees.size >= 1, (judges, audits, referees)
        assert len(before["trial_id"]) < budget
        resumed = coordinator(ep, out, "--resume", str(out))
        helpers = [worker(ep, "pc", f"w{i}") for i in (3, 4)]   # every engine, two more identities
        procs += [resumed, *helpers]
        assert resumed.wait(240) == 0
        with Hdf5Storage.open_read(out) as s:
            cols, ev = s.columns(), s.evaluations()
        assert cols["trial_id"].tolist() == list(range(budget))       # exactly its budget, no row twice
        assert set(cols["status"].tolist()) == {b"complete"}
        after = {(int(t), k.decode()) for t, k in zip(ev["trial_id"][n_rows_before:], ev["kind"][n_rows_before:],
                                                      strict=True)}
        by = set(ev["worker_id"][n_rows_before:].tolist())
        assert by <= {b"w3", b"w4"}, by
        for kind, rows in (("judge", judges), ("audit", audits), ("referee", referees)):
            missing = [int(t) for t in rows if (int(t), kind) not in after]
            # a judge may be left unrun only because its set stopped being the best before a worker took it
            if kind == "judge":
                missing = [t for t in missing if cols["verification"][t] != b""]
            assert not missing, (kind, missing, sorted(after))
        for tid in referees.tolist():   # the third identity sided with w1: the liar's audit is overruled
            assert cols["audit"][tid] == b"overruled", (tid, cols["audit"][tid])
        assert not np.isin(cols["audit"], (b"pending", b"disputed")).any()
        assert not (cols["verification"] == b"pending").any()
    finally:
        stop(*procs)
