"""bench/time_to_quality.py, bench/control_split.py and bench/batch_worlds.py, reduced: the seeds' median rule,
the process tree's CPU time, and the in-trial split and the batch both keeping the trials' bits."""

from __future__ import annotations

import importlib.util
import json
import os
import signal
import subprocess
import sys
import time

from tests.coordinator_tests.procs import ROOT


def _bench(name: str):
    spec = importlib.util.spec_from_file_location(f"{name}_bench", ROOT / "bench" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _run(*args: str) -> dict:
    r = subprocess.run([sys.executable, *args], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_the_median_seed_counts_a_seed_that_never_got_there_as_the_slowest():
    ttq = _bench("time_to_quality")
    runs = [{"wall_s": w, "cpu_s": c, "best_cm_s": b, "exit_code": 130, "judged": []}
            for w, c, b in ((300.0, 550.0, 9.9), (None, None, 7.0), (100.0, 190.0, 10.5))]
    row = ttq.summarise("tetraspine", runs)
    assert row["median_wall_s"] == 300.0  # of 100, 300 and never: the middle one is 300
    assert row["best_judged_cm_s"] == 9.9 and row["paper_speed_cm_s"] == 9.46
    assert row["wall_s_to_paper_speed"] == [300.0, None, 100.0] and row["cpu_s_to_paper_speed"][2] == 190.0
    runs[0]["wall_s"] = None  # two of three never reached it: no median
    assert ttq.summarise("tetraspine", runs)["median_wall_s"] is None


def test_the_search_tree_cpu_counts_a_busy_grandchild():
    ttq = _bench("time_to_quality")
    busy = ("import time\nwhile time.process_time() < 0.6: pass\nprint('done', flush=True)\ntime.sleep(60)")
    root = subprocess.Popen(["sh", "-c", f'"{sys.executable}" -c "{busy}"'], stdout=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        assert root.stdout.readline().strip() == "done"  # the grandchild spent 0.6 CPU s and lives on
        time.sleep(0.05)
        assert 0.55 <= ttq.tree_cpu_s(root.pid) < 30.0  # /proc counts in clock ticks (10 ms), rounded down
    finally:
        os.killpg(root.pid, signal.SIGKILL)  # the shell and the grandchild, by the group the test started
        root.wait()


def test_the_in_trial_split_keeps_the_trials_bits():
    out = _run("bench/control_split.py", "--spines", "tetraspine-ntrt", "--seconds", "0.3", "--repeats", "1")
    row = out["spines"]["tetraspine-ntrt"]
    assert row["same_distance"]  # the timed copy of the loop computes what the production loop does
    us = row["us_per_step"]
    assert all(us[k] > 0 for k in ("whole", "mj_step", "law", "cpg"))
    # parts and whole are timed on different runs (the whole on the production trial): their sum is a benchmark's
    # figure, not a test's, so only the definition of the share is held here
    assert abs(row["control_share"] - (1 - us["mj_step"] / us["whole"])) < 1e-12


def test_a_batch_of_worlds_gives_the_single_trials_bits():
    out = _run("bench/batch_worlds.py", "--spine", "tetraspine-ntrt", "--batches", "2", "--seconds", "0.2",
               "--repeats", "1")
    row = out["batches"]["2"]
    assert row["same_distances"] and row["batch_cpu_s_per_world_sim_s"] > 0
