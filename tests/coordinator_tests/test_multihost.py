"""A search across three hosts (network namespaces): latency, loss, a worker killed, a host cut off
for 8 s that comes back, then cut off again until the run has ended on the other host. Every trial is
stored exactly once and every process ends by itself, the cut-off worker once the coordinator has been
silent for its --coordinator-timeout, after the partition healed."""

from __future__ import annotations

import secrets
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from spinefarm.storage.hdf5_reader import read_run
from tests.coordinator_tests.helpers import wait_for
from tests.coordinator_tests.procs import ROOT, status
from tests.netns import ThreeHosts, netns_unavailable

pytestmark = pytest.mark.integration
_WHY_NOT = netns_unavailable()
TRIALS = 48
COORDINATOR_TIMEOUT_S = 18.0  # the workers' --coordinator-timeout: the 8 s cut that heals plus reconnecting (1-5 s)


def stored_by(out, worker_id: str) -> int:
    _, cols = read_run(out)
    return int(np.count_nonzero((cols["worker_id"] == worker_id.encode()) & (cols["status"] == b"complete")))


def spawn(hosts: ThreeHosts, ns: str, *args: str) -> subprocess.Popen:
    return subprocess.Popen([*hosts.exec_args(ns), sys.executable, "-m", "spinefarm", *args], cwd=ROOT,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


@pytest.mark.skipif(_WHY_NOT is not None, reason=f"no network namespaces here: {_WHY_NOT}")
def test_three_hosts_with_latency_loss_a_kill_and_partitions_healing_during_and_after_the_run(tmp_path):
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
        common = ("--run", "netns", "--batch", "1", "--exit-when-done", "--coordinator-timeout",
                  f"{COORDINATOR_TIMEOUT_S:g}", "--credentials", str(creds))
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
        before_heal = stored_by(out, "b1")
        hosts.cut("b", cut=False)                  # ... for 8 s, then comes back
        # Host A alone then finishes the last few trials well within the cut-off worker's timeout.
        wait_for(lambda: stored_by(out, "b1") > before_heal and status(out)["trials_complete"] >= TRIALS - 10,
                 timeout_s=30, poll_s=0.1, what="host B's worker storing trials again after the partition healed")
        hosts.cut("b")                             # cut off again: the run ends on host A alone ...
        t_cut = time.monotonic()
        assert coord.wait(120) == 0, coord.stderr.read()[-3000:]
        assert a1.wait(60) == 0, a1.stderr.read()[-3000:]
        assert b1.poll() is None, "host B's worker left before the partition healed"
        hosts.cut("b", cut=False)                  # ... and the partition heals after the run has ended
        assert b1.wait(COORDINATOR_TIMEOUT_S + 30) == 0, b1.stderr.read()[-3000:]
        t_b1 = time.monotonic() - t_cut
        # Its last contact was before the cut: silence for the timeout, one more unanswered query, the
        # final attempt to hand over its unacknowledged result (5 s query timeouts each).
        assert t_b1 <= COORDINATOR_TIMEOUT_S + 15, t_b1
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
