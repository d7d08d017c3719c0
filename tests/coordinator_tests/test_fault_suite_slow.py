"""The whole fault suite (bench/faults.py) with its figures asserted: kills of workers, of the
coordinator and of everything at once over several runs; a frozen worker; forged and malformed
messages; a full disk; a disk that dies mid-run; damaged files. Minutes, so `slow` (run with -m slow)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.coordinator_tests.procs import ROOT

pytestmark = pytest.mark.slow


def test_the_fault_suite_loses_nothing_accepts_nothing_forged_and_never_hangs():
    r = subprocess.run([sys.executable, str(ROOT / "bench" / "faults.py"), "--runs", "3", "--trials", "200",
                        "--seed", "3"], cwd=ROOT, capture_output=True, text=True, timeout=1800)
    assert r.returncode == 0, r.stderr[-3000:]
    fig = json.loads(r.stdout.strip().splitlines()[-1])
    kills = fig["kills"]
    assert kills["kills_survived"] >= 10 and kills["coordinator_kills"] >= 1
    assert kills["lost"] == 0 and kills["duplicated"] == 0 and kills["runs_at_exact_budget"] == 3
    assert all(s < 5.0 for s in fig["reissue"]["reissue_latency_s"])
    h = fig["hostile"]
    assert h["forged_rejected"] == h["forged_sent"] and not h["forged_best_stored"]
    assert h["malformed_error_replies"] == h["malformed_sent"]
    d = fig["disk"]
    if "skipped" not in d:
        assert d["exit_code"] == 1 and d["says_why"] and d["lost"] == 0 and not d["segfault"]
    f = fig["files"]
    assert all(v["exit_code"] == 2 for k, v in f.items() if k != "wall_s")
    assert f["truncated"]["seconds"] < 5 and f["garbled_header"]["seconds"] < 20
    pc = fig["power_cut"]
    if "skipped" not in pc:
        assert pc["exit_code"] == 1 and pc["says_why"] and not pc["hung"]
        assert pc["lost"] == 0 and pc["duplicated"] == 0 and pc["acknowledged"] >= 300
        assert pc["resumes"] == "yes"
