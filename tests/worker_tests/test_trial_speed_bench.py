"""bench/trial_speed.py --spines, reduced: every built-in, including one whose strings need the automatic step
(tetraspine-hardware), gets its per-engine costs and the rod pairs `reach` models, at that step."""

from __future__ import annotations

import json
import subprocess
import sys

from tests.coordinator_tests.procs import ROOT


def test_spines_with_a_robot_that_needs_the_automatic_step():
    r = subprocess.run([sys.executable, "bench/trial_speed.py", "--spines", "tetraspine-hardware,tetraspine-ntrt",
                        "--tier-seconds", "0.05", "--repeats", "1"], cwd=ROOT, capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    spines = json.loads(r.stdout.strip().splitlines()[-1])["spines"]
    hardware, ntrt = spines["tetraspine-hardware"], spines["tetraspine-ntrt"]
    assert all(dt < 5.1e-4 for dt in hardware["dt_s"].values())  # below its strings' stable step
    assert ntrt["dt_s"]["bullet"] == 1e-3
    for row in (hardware, ntrt):
        assert row["bullet_cpu_s_per_sim_s"] > 0 and row["mujoco_speedup"] > 0
        split = row["mujoco_split_us_per_step"]  # parts of one step: each less than the whole
        assert 0 < split["mj_step"] < split["whole"] and 0 < split["control_law"] < split["whole"]
        assert row["guard_check_us"]["exact"] > 0 and row["guard_check_us"]["compiled"] > 0
        assert abs(row["control_share"] - (1 - split["mj_step"] / split["whole"])) < 1e-12
        pairs = row["mujoco_reach_rod_pairs"]
        assert 0 < pairs["modelled"] <= pairs["of"]
