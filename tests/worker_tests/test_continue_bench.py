"""bench/continue_rungs.py at a tiny budget: continuation on and off side by side, its figures as the ladder says.
Two real searches (~30 s): slow."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.coordinator_tests.procs import ROOT

pytestmark = pytest.mark.slow


def test_the_bench_prints_what_continuation_saved_and_nothing_when_off():
    proc = subprocess.run([sys.executable, "bench/continue_rungs.py", "--rungs", "0.5,1.5", "--duration", "1.5",
                           "--eta", "2", "--settle", "0.2", "--trials", "8"], cwd=ROOT, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout)
    on, off = (next(r for r in out["runs"] if r["continue"] is flag) for flag in (True, False))
    assert off["continued"] == 0 and off["sim_s_run_per_set"] == off["sim_s_asked_per_set"]
    # by hand: each continued promotion (0.5 s rung -> 1.5 s) skips its settle and rung, 0.2 + 0.5 s
    assert on["continued"] >= 1
    skipped = on["sim_s_asked_per_set"] - on["sim_s_run_per_set"]
    assert skipped == pytest.approx(on["continued"] * 0.7 / on["parameter_sets"], abs=2e-3)
    assert out["end_bytes"] > 0 and out["saving"]["sim_s_run"] > 0
