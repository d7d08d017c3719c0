"""bench/settle.py: the claim of docs/engines.md that a 1 s settle removes a still robot's settling motion, on
both engines, while the first second unsettled moves it by centimetres."""

from __future__ import annotations

import json
import subprocess
import sys

from tests.coordinator_tests.procs import ROOT


def test_a_one_second_settle_leaves_a_still_robot_still_on_both_engines():
    r = subprocess.run([sys.executable, "bench/settle.py"], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    rows = json.loads(r.stdout.strip().splitlines()[-1])["rows"]
    for engine in ("bullet", "mujoco"):
        by = {(row["settle_s"], row["scored_s"]): row for row in rows[engine]}
        assert all(row["status"] == "complete" for row in by.values()), rows[engine]
        assert by[(0.0, 1.0)]["distance_cm"] > 3.0  # settling motion: centimetres
        # a half-second settle leaves a fraction of it, a whole second nothing the score would see
        assert by[(0.5, 1.0)]["distance_cm"] < 0.2 * by[(0.0, 1.0)]["distance_cm"]
        assert by[(1.0, 1.0)]["distance_cm"] < 0.01
