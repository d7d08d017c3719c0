"""bench/ladder.py: its rank and survival arithmetic on hand-made distances, and a reduced run whose rungs
read from the full trial give the bits of trials of the rung's own length."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys

import numpy as np

from tests.coordinator_tests.procs import ROOT


def _bench():
    spec = importlib.util.spec_from_file_location("ladder_bench", ROOT / "bench" / "ladder.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_rank_and_survival_on_hand_made_distances():
    bench = _bench()
    # one seed, four gaits; rung 1 s ranks them exactly backwards, rung 2 s exactly right
    dist = np.array([[[1.0, 4.0, 4.0], [2.0, 3.0, 3.0], [3.0, 2.0, 2.0], [4.0, 1.0, 1.0]]])
    table = bench.rung_table(dist, [1.0, 2.0, 30.0], [2, 4])
    assert table["1"]["spearman_rho"] == [-1.0] and table["2"]["spearman_rho"] == [1.0]
    assert table["1"]["best_survives"] == {"2": 0, "4": 0} and table["2"]["best_survives"] == {"2": 1, "4": 1}
    ladders = {(tuple(lad["rungs"]), lad["eta"]): lad for lad in bench.ladders(dist, [1.0, 2.0, 30.0], [2])}
    assert ladders[((2.0, 30.0), 2)]["best_survives"] == 1 and ladders[((1.0, 30.0), 2)]["best_survives"] == 0
    # cost per gait: 1 s for all, 2 s for the best half, 30 s for the best quarter
    assert ladders[((1.0, 2.0, 30.0), 2)]["sim_s_per_gait"] == 1.0 + 2.0 / 2 + 30.0 / 4
    assert ladders[((1.0, 2.0, 30.0), 2)]["sim_s_per_gait_continued"] == 1.0 + 1.0 / 2 + 28.0 / 4
    assert ladders[((1.0, 2.0, 30.0), 2)]["best_survives"] == 0


def test_a_reduced_run_reads_its_rungs_from_the_full_trial_to_the_bit():
    r = subprocess.run([sys.executable, "bench/ladder.py", "--spines", "tetraspine", "--controller", "sidewinding",
                        "--dt", "0.002", "--engine-option", "segment_contacts=off", "--settle", "0.2",
                        "--duration", "1", "--lengths", "0.3,0.5", "--seeds", "2", "--gaits", "4", "--jobs", "1"],
                       cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    row = json.loads(r.stdout.strip().splitlines()[-1])["spines"]["tetraspine"]
    assert row["prefix_exact"] and row["lengths_s"] == [0.3, 0.5, 1.0]
    for rung in row["rungs"].values():
        assert all(-1.0 <= rho <= 1.0 for rho in rung["spearman_rho"])
        assert all(0 <= n <= 2 for n in rung["best_survives"].values())
