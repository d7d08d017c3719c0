"""`spinefarm calibrate`: real trials on both engines, tiny calibrations."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from spinefarm.robot.morphology.registry import builtin_path, load_morphology
from spinefarm.worker.calibrate import agreement, decide

from tests.coordinator_tests.procs import ROOT

TINY = ("--gaits", "4", "--search-trials", "2", "--bests", "1", "--duration", "0.5", "--settle", "0.2")


def spinefarm(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "spinefarm", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=timeout)


def test_agreeing_tiers_pass_and_disagreeing_ones_fall_back():
    rng = np.random.default_rng(1)
    bullet = rng.uniform(0.02, 1.0, 30)
    agree = agreement(bullet, bullet * rng.uniform(0.97, 1.03, 30))
    assert agree["spearman"] > 0.95 and decide(agree)[0] == "mujoco", agree
    shuffled = agreement(bullet, rng.permutation(bullet))
    engine, why = decide(shuffled)
    assert engine == "bullet" and "rho" in why and "overlap" in why, why
    half = agreement(bullet, 0.55 * bullet)  # ranks alike, goes half as far (the ribbed spine's case)
    engine, why = decide(half)
    assert half["spearman"] == pytest.approx(1.0) and engine == "bullet" and "ratio 0.550" in why, why
    still = agreement(np.full(12, 0.001), np.full(12, 0.001))  # nothing moves: no ratio, no pass
    assert still["median_distance_ratio"] is None and decide(still)[0] == "bullet"


def test_calibrate_a_builtin_and_a_spec_file(tmp_path):
    spec = tmp_path / "stiff.yaml"
    spec.write_text(builtin_path("tetraspine-ntrt").read_text().replace("name: tetraspine-ntrt", "name: stiff", 1))
    seen = {}
    for robot in ("tetraspine-ntrt", str(spec)):
        r = spinefarm("calibrate", robot, *TINY, "--jobs", "1", "--json")
        assert r.returncode == 0, r.stderr[-2000:]
        out = json.loads(r.stdout.strip().splitlines()[-1])
        assert out["cached"] is False and out["spec_hash"] == load_morphology(robot).spec_hash()
        assert len(out["distance_m"]["mujoco"]) == len(out["distance_m"]["bullet"]) == 5  # 4 random + 1 best
        assert out["decision"] == decide(out)[0] and out["reason"] == decide(out)[1]
        for tier in ("mujoco", "bullet"):
            assert out["tiers"][tier]["cpu_s_per_sim_s"] > 0
        seen[robot] = out
    again = spinefarm("calibrate", "tetraspine-ntrt", *TINY, "--json")
    cached = json.loads(again.stdout.strip().splitlines()[-1])
    assert cached["cached"] is True and cached["distance_m"] == seen["tetraspine-ntrt"]["distance_m"]
    text = spinefarm("calibrate", "tetraspine-ntrt", *TINY)
    assert "[cached]" in text.stdout and "decision: " in text.stdout and "Spearman rho" in text.stdout
