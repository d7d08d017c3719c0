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


def test_ranks_against_the_judge_beside_the_screen_on_hand_made_distances():
    bench = _bench()
    # one seed, four gaits: the screen ranks its own full length exactly, the judge ranks them exactly backwards
    dist = np.array([[[1.0, 1.0], [2.0, 2.0], [3.0, 3.0], [4.0, 4.0]]])
    judge = np.array([[4.0, 3.0, 2.0, 1.0]])
    table = bench.rung_table(dist, [1.0, 30.0], [2], judge, "_judge")
    assert table["1"]["spearman_rho_judge"] == [-1.0] and table["30"]["spearman_rho_judge"] == [-1.0]
    assert table["1"]["best_survives_judge"] == {"2": 0}  # the judge's best (gait 0) is the screen's worst
    lad = bench.ladders(dist, [1.0, 30.0], [2], judge)[0]
    assert (lad["best_survives"], lad["best_survives_judge"]) == (1, 0)
    screen = bench.rung_table(dist, [1.0, 30.0], [2])
    assert bench.choose(screen, [lad], 1, 0.8) == lad
    assert bench.choose(table, [lad], 1, 0.8, "_judge") is None


def _trial_cm(engine: str, *flags: str) -> float:
    cmd = [sys.executable, "-m", "spinefarm", "trial", "tetraspine", "--params", "examples/gaits/tetraspine.json",
           "--engine", engine, "--duration", "0.6", "--settle", "0.2", "--json", *flags]
    r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout)["distance_cm"]


def test_the_judge_option_runs_the_judges_engine_and_step_as_spinefarm_trial_does():
    # --around with no spread: every gait is the shipped one, so both medians are that gait's trials
    r = subprocess.run([sys.executable, "bench/ladder.py", "--spines", "tetraspine", "--controller", "sidewinding",
                        "--dt", "0.002", "--engine-option", "segment_contacts=off", "--settle", "0.2",
                        "--duration", "0.6", "--lengths", "0.2", "--seeds", "1", "--gaits", "1", "--jobs", "1",
                        "--around", "examples/gaits/tetraspine.json", "--spread", "0", "--judge"],
                       cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    row = out["spines"]["tetraspine"]
    assert out["around"] == "examples/gaits/tetraspine.json" and "best_survives_judge" in row["ladders"][0]
    assert set(row["rungs"]) == {"0.2", "0.6"} and "spearman_rho_judge_median" in row["rungs"]["0.2"]
    assert row["judge_distance_cm_median"] == _trial_cm("bullet", "--dt", "0.00025")
    assert row["full_distance_cm_median"] == _trial_cm("mujoco", "--dt", "0.002",
                                                       "--engine-option", "segment_contacts=off")
    assert abs(row["judge_distance_cm_median"] - row["full_distance_cm_median"]) > 1e-6  # two engines ran


def test_a_gait_of_another_robot_is_refused_in_one_line():
    r = subprocess.run([sys.executable, "bench/ladder.py", "--spines", "tetraspine", "--seeds", "1", "--gaits", "1",
                        "--around", "examples/gaits/ribbed.json", "--jobs", "1"],
                       cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode != 0
    assert "a gait of 'ribbed' received, one of 'tetraspine' expected" in r.stderr.strip().splitlines()[-1]
