"""bench/coordinator_throughput.py runs its fsync comparison on a setting its main sweep measured already."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.coordinator_tests.procs import ROOT


@pytest.mark.slow
def test_the_fsync_comparison_repeats_a_measured_setting_in_a_file_of_its_own(tmp_path):
    # The sweep and the comparison both measure 1 worker with auto batches: with a file named by the setting
    # alone the comparison died on "run file already exists" (with --workers 2 8 --batch 0 --no-resume too).
    r = subprocess.run([sys.executable, str(ROOT / "bench" / "coordinator_throughput.py"), "--workers", "1",
                        "--batch", "0", "--trials", "100", "--no-physics", "--fsync-workers", "1", "--fsync-batch",
                        "0", "--no-resume", "--dir", str(tmp_path)], cwd=ROOT, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert [(m["workers"], m["batch"], m["complete"]) for m in out["sphere"]] == [(1, 0, 100)]
    [cost] = out["fsync"]
    assert (cost["workers"], cost["batch"]) == (1, 0)
    assert cost["without_fsync_trials_per_s"] > 0 and cost["with_fsync_trials_per_s"] > 0
    assert not list(tmp_path.iterdir())  # its run files go with its temporary directory


def test_the_resume_step_reopens_a_killed_writers_file(tmp_path):
    """The bench's "killed" writer lives in its own process: its run lock must go, as a killed process's does,
    or the resume it times is refused ("being written by another coordinator")."""
    import importlib.util

    path = ROOT / "bench" / "coordinator_throughput.py"
    spec = importlib.util.spec_from_file_location("coordinator_throughput", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    out = bench.resume_cost(tmp_path, 300)
    assert out["resume_rows"] == 300 and 0 < out["resume_s"] < 60
