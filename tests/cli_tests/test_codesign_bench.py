"""bench/codesign.py as measured: each search a real `spinefarm search` whose run file it keeps, the judged
trial exported and re-run by the product's commands; a ladder that does not end at the trial is refused."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

import spinefarm
from tests.cli_tests.test_codesign import ROOT


def bench(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(ROOT / "bench" / "codesign.py"), *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=900)


def test_a_ladder_that_does_not_end_at_the_trial_is_refused_in_one_line():
    r = bench("--duration", "5", "--rungs", "1,2")
    assert r.returncode == 2
    assert r.stderr.strip().splitlines()[-1].endswith("--rungs 1,2: the last rung must be the full trial, "
                                                       "--duration 5.0")


@pytest.mark.slow  # two searches, a judge, two exports and re-runs: 15-20 s measured at a load of 7
def test_kept_run_files_and_the_judged_trial_exported_and_rerun(tmp_path: Path):
    r = bench("--budget", "6", "--seeds", "1", "--first-seed", "3", "--duration", "1", "--rungs", "0.5,1",
              "--eta", "2", "--engine", "mujoco", "--dt", "0.002", "--controller", "sidewinding", "--judged", "1",
              "--episodes", "2", "--keep", str(tmp_path))
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout.strip().splitlines()[-1])
    for mode in ("gait_only", "codesign"):
        (search,) = out[mode]
        df = spinefarm.load_run(tmp_path / f"{mode}-seed3.h5")  # kept, read independently of the bench
        assert search["parameter_sets"] == (df["rung"] == 0).sum() == 6
        # at least the best half (3 of 6) promoted to 1 s (asynchronous halving may promote more): the front's pool
        full = (df["rung"] == 1) & (df["status"] == "complete")
        assert search["evaluations"] == len(df) and search["full_length_complete"] == full.sum() >= 3
        assert {f["trial_id"] for f in search["front"]} <= set(df.index[full])
        exported = search["exported"]
        assert exported["stored_distance_m"] == df.loc[exported["trial_id"], "distance_m"]
        assert exported["bit_for_bit"] and Path(exported["gait"]).is_file()
        assert (exported["spec"] is not None) == (mode == "codesign")
