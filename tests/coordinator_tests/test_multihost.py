"""A search across three hosts (network namespaces): latency, loss, a worker killed, a host cut off
for 8 s that comes back. Every trial is stored exactly once and every process ends by itself."""

from __future__ import annotations

import secrets
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from storage.hdf5 import read_run
from tests.coordinator_tests.helpers import wait_for
from tests.coordinator_tests.procs import ROOT, status
from tests.netns import ThreeHosts, netns_unavailable

pytestmark = pytest.mark.integration
_WHY_NOT = netns_unavailable()
TRIALS = 48


def spawn(hosts: ThreeHosts, ns: str, *args: str) -> subprocess.Popen:
    return subprocess.Popen([*hosts.exec_args(ns), sys.executable, "-m", "cli.main", *args], cwd=ROOT,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


@pytest.mark.skipif(_WHY_NOT is not None, reason=f"no network namespaces here: {_WHY_NOT}")
def test_three_hosts_with_latency_loss_a_kill_and_a_partition_that_heals(tmp_path):
    creds = tmp_path / "credentials"
    creds.write_text(f"coordinator:{secrets.token_hex(16)}\n")
    creds.chmod(0o600)
    out = tmp_path / "run.h5"
    hosts = ThreeHosts().open()
    procs: list[subprocess.Popen] = []
    try:
        coord = spawn(hosts, hosts.hub, "coordinator", "sphere:4", "--trials", str(TRIALS), "--duration", "0.4",
                      "--run-id", "netns", "--out", str(out), "--listen", hosts.coordinator_listen, "--api-port", "-1",
                      "--lease", "20", "--credentials", str(creds), "--quiet")
        procs.append(coord)
        wait_for(lambda: (status(out) or {}).get("state") == "running", timeout_s=30, what="the coordinator")
        common = ("--run", "netns", "--batch", "1", "--exit-when-done", "--coordinator-timeout", "15",
                  "--credentials", str(creds))
        a1 = spawn(hosts, hosts.host("a"), "worker", "--connect", hosts.endpoint("a"),
                   "--worker-id", "a1", *common)
        a2 = spawn(hosts, hosts.host("a"), "worker", "--connect", hosts.endpoint("a"),
                   "--worker-id", "a2", *common)
        b1 = spawn(hosts, hosts.host("b"), "worker", "--connect", hosts.endpoint("b"),
                   "--worker-id", "b1", *common)
        procs += [a1, a2, b1]
        wait_for(lambda: {w["worker_id"] for w in (status(out) or {}).get("workers", [])} >= {"a1", "a2", "b1"}
                 and status(out)["trials_complete"] >= 4, timeout_s=40, what="three workers at work")
        a2.send_signal(signal.SIGKILL)             # a worker dies mid-trial
        hosts.cut("b")                             # host B is cut off ...
        t_cut = time.monotonic()
        wait_for(lambda: any(w["worker_id"] == "b1" and not w["alive"] for w in status(out)["workers"]),
                 timeout_s=20, what="the coordinator to drop host B's worker")
        time.sleep(max(0.0, 8.0 - (time.monotonic() - t_cut)))
        hosts.cut("b", cut=False)                  # ... for 8 s, then comes back
        assert coord.wait(120) == 0, coord.stderr.read()[-3000:]
        for w in (a1, b1):
            assert w.wait(60) == 0, w.stderr.read()[-3000:]
        final = status(out)
        _, cols = read_run(out)
        assert len(cols["trial_id"]) == TRIALS and np.array_equal(cols["trial_id"], np.arange(TRIALS))
        assert set(cols["status"].tolist()) == {b"complete"}, final
        assert final["trials_complete"] == TRIALS and final["trials_reissued"] >= 1
        assert {w.decode() for w in cols["worker_id"]} <= {"a1", "a2", "b1"}
        assert b"b1" in set(cols["worker_id"].tolist())
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
            p.wait(10)
        hosts.close()
