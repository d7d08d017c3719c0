"""`spinefarm calibrate` and `search --engine auto`: real trials on both engines, tiny calibrations."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from spinefarm.api.app import create_app
from spinefarm.protocol.engine_choice import EngineChoice
from spinefarm.protocol.errors import ConfigError
from spinefarm.protocol.settings import RunSettings
from spinefarm.robot.morphology.registry import builtin_path, load_morphology
from spinefarm.storage.hdf5_reader import read_run
from spinefarm.worker.tools.calibrate import agreement, decide
from tests.coordinator_tests.procs import ROOT
from tests.http_server import served

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


def test_search_engine_auto_stores_its_choice_and_resumes_with_it(tmp_path):
    out = tmp_path / "auto.h5"
    tiny = [f"--calibrate-{a[2:]}" if a.startswith("--") else a for a in TINY]
    r = spinefarm("search", "tetraspine-ntrt", "--trials", "3", "--workers", "1", "--duration", "0.5",
                  "--out", str(out), "--api-port", "-1", "--quiet", "--no-verify", *tiny)
    assert r.returncode == 0, r.stderr[-2000:]
    meta, cols = read_run(out)
    choice = meta.settings.engine_choice.to_dict()
    assert choice["mode"] == "auto" and choice["engine"] == decide(choice)[0]
    assert meta.trial_config.get("engine", "bullet") == choice["engine"]
    assert (choice["rungs_added"] is not None) == (choice["engine"] == "mujoco")
    assert {e.decode() if isinstance(e, bytes) else e for e in cols["engine"]} == {choice["engine"]}
    assert f"engine auto chose {choice['engine']}" in r.stdout + r.stderr
    assert choice["screen_fit"] is None and "screen fitted" not in r.stderr  # a built-in's screen is not fitted
    with served(create_app([out])) as client:  # the dashboard's meta carries the choice
        run_id = client.get("/runs").json()[0]["run_id"]
        assert client.get(f"/runs/{run_id}/meta").json()["engine_choice"] == choice
    resumed = spinefarm("search", "--resume", str(out), "--trials", "5", "--workers", "1", "--api-port", "-1",
                        "--quiet")
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    meta2, cols2 = read_run(out)
    assert meta2.settings.engine_choice.to_dict() == choice and len(cols2["engine"]) >= 5
    assert "calibrating" not in resumed.stderr  # a resumed run keeps its tier
    assert f"engine auto chose {choice['engine']}" in resumed.stdout  # and says so in its report


def test_an_explicit_engine_is_not_calibrated(tmp_path):
    out = tmp_path / "bullet.h5"
    r = spinefarm("search", "tetraspine-ntrt", "--engine", "bullet", "--trials", "1", "--workers", "1",
                  "--duration", "0.3", "--out", str(out), "--api-port", "-1", "--quiet", "--no-verify")
    assert r.returncode == 0, r.stderr[-2000:]
    assert "calibrating" not in r.stderr and read_run(out)[0].settings.engine_choice is None


def test_the_choice_is_typed_settings_that_round_trip_and_refuse_bad_fields():
    result = {"decision": "bullet", "spearman": 0.5, "top_overlap": 3, "top_k": 10, "median_distance_ratio": 0.55,
              "n_moving": 7, "n_random": 40, "n_bests": 10, "spec_hash": "abc", "reason": "the fast tier disagrees",
              "tiers": {"mujoco": {"cpu_s_per_sim_s": 0.02, "step_error": 0.01},
                        "bullet": {"cpu_s_per_sim_s": 0.05, "step_error": None}}}
    choice = EngineChoice.from_calibration(result, cached=True, rungs_added=None)
    settings = RunSettings(engine_choice=choice)
    assert RunSettings.from_dict(json.loads(json.dumps(settings.to_dict()))) == settings
    assert RunSettings.from_dict({k: v for k, v in settings.to_dict().items() if k != "engine_choice"}) \
        == RunSettings()  # a run stored before the choice existed reads back without one
    assert "engine auto chose bullet" in choice.describe() and "[calibration cached]" in choice.describe()
    assert "shipped" not in choice.describe()  # a cached calibration is not called the package's
    shipped = EngineChoice.from_calibration({**result, "shipped": True}, cached=True, rungs_added=None)
    assert shipped.shipped and "[shipped calibration]" in shipped.describe()
    assert "[calibration cached]" not in shipped.describe()
    with pytest.raises(ConfigError, match="unknown fields"):
        EngineChoice.from_dict({**choice.to_dict(), "colour": "red"})
    with pytest.raises(ConfigError, match="unknown tier"):
        EngineChoice.from_dict({**choice.to_dict(), "engine": "auto"})


def test_a_change_of_the_simulating_code_calibrates_again(tmp_path):
    """The cache is keyed by the simulating code's contents: an engine's model that changes (a friction cone,
    say) is not judged by a calibration of the old one."""
    from spinefarm.worker.tools.calibrate import (
        CalibrationSettings,
        cache_path,
        code_digest,
        simulating_code_digest,
    )

    engines = tmp_path / "engines"
    engines.mkdir()
    (engines / "mujoco.py").write_text("CONE = 'pyramidal'\n")
    (engines / "notes.txt").write_text("not code\n")
    before = code_digest([engines], ("numpy",))
    (engines / "notes.txt").write_text("still not code\n")
    assert code_digest([engines], ("numpy",)) == before
    (engines / "mujoco.py").write_text("CONE = 'elliptic'\n")
    assert code_digest([engines], ("numpy",)) != before
    assert code_digest([engines], ("numpy", "no-such-package")) != code_digest([engines], ("numpy",))
    assert cache_path("tetraspine-ntrt", CalibrationSettings()).stem.endswith(simulating_code_digest())


def test_a_cache_that_cannot_be_written_keeps_the_figures(tmp_path):
    """A read-only home (a container's): the calibration's figures still come out, with a warning, instead of
    being computed and thrown away (and `search --engine auto` falling back to Bullet)."""
    blocked = tmp_path / "a-file"
    blocked.write_text("x")  # no folder can be made below a file
    env = {**os.environ, "SPINEFARM_CACHE_DIR": str(blocked / "cache")}
    r = subprocess.run([sys.executable, "-m", "spinefarm", "calibrate", "tetraspine-ntrt", *TINY, "--jobs", "1",
                        "--json"], cwd=ROOT, capture_output=True, text=True, timeout=300, env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out["cached"] is False and out["decision"] == decide(out)[0]
    assert "the calibration is not cached" in r.stderr and "SPINEFARM_CACHE_DIR" in r.stderr
