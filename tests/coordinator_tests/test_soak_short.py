"""The soak (bench/soak.py) in a short form: faults of every kind for 0.4 min, then the run's exact budget,
nothing lost, duplicated or forged, nothing left running, nothing restarted but what the schedule killed."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys

from tests.coordinator_tests.procs import ROOT, log_tail
from tests.netns import netns_unavailable


def _log_tails(workdir, lines: int = 12) -> str:
    """The last lines of the coordinator's and each worker's log (pytest's folder for them does not outlive CI)."""
    parts = []
    for log in sorted([workdir / "coordinator.log", *workdir.glob("w*.log")]):
        if log.exists():
            parts.append(f"--- {log.name}\n" + log_tail(log, lines))
    return "\n".join(parts)


def test_a_short_soak_reaches_its_exact_budget_through_every_fault(tmp_path):
    netns = netns_unavailable() is None
    r = subprocess.run([sys.executable, str(ROOT / "bench" / "soak.py"), "--minutes", "0.4", "--seed", "2", "--dir",
                        str(tmp_path), *([] if netns else ["--no-netns"])], cwd=ROOT, capture_output=True, text=True,
                       timeout=400)
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert not out["timed_out"] and out["exact_budget"], out
    assert out["lost"] == 0 and out["duplicated"] == 0 and out["forged_complete"] == 0, out
    assert out["hung_processes"] == [] and out["waiting"] == 0, out
    # every worker heard "done", none waited out its timeout
    assert out["workers_timed_out"] == 0, (out, _log_tails(tmp_path))
    faults = out["faults"]
    assert faults["unexpected_coordinator_exits"] == 0 and faults["unexpected_worker_exits"] == 0, out
    assert faults.get("coordinator_kill", 0) >= 1 and faults.get("forge") == 1, out
    assert faults.get("end_stop") == 1, out  # a worker frozen as the run ended: it too heard "done"
    assert out["failed_timeout"] >= 1 and out["failed_crashed"] >= 1, out  # the poison bands were hit
    assert out["failed_outside_bands"] == 0, out
    if netns:
        assert faults.get("partition") == 1, out


def test_a_run_faster_than_planned_still_gets_each_once_only_fault():
    spec = importlib.util.spec_from_file_location("soak", ROOT / "bench" / "soak.py")
    soak = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(soak)
    every = set(soak.ONCE)
    assert soak.due_once(every, 0.0, 0.0) == []
    assert soak.due_once(every, 0.36, 0.0) == ["forge", "coordinator_kill"]   # on time
    assert soak.due_once(every, 0.05, 0.5) == ["forge", "coordinator_kill", "partition"]  # the run is ahead
    assert soak.due_once({"partition"}, 0.05, 0.5) == ["partition"]
    # a worker frozen as the run ends: a few seconds before, by the coordinator's ETA, from half way on
    assert not soak.end_stop_due(0.4, 1.0) and not soak.end_stop_due(0.6, 30.0) and not soak.end_stop_due(0.6, None)
    assert soak.end_stop_due(0.6, 9.0) and soak.end_stop_due(0.9, None)
