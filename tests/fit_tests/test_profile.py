"""A profile (robot.profile) changes a trial exactly as the same constants written into a spec file do, in both
engines; values outside their plausible ranges are refused in one line; a search's run file and a calibration's
cache key record the profile's hash, and the search's workers apply it."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from spinefarm.cli.main import main
from spinefarm.robot.profile import load_profile, profile_hash
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.tools.calibrate import CalibrationSettings

ROOT = Path(__file__).resolve().parents[2]
PROFILE = """constants:
  ground_friction: 0.7
  rod_friction: 0.8
  rod_density_kg_per_cm3: 0.012
  string_stiffness_n_per_m.outer: 1500
  string_damping_n_s_per_m: 12
"""
SPEC = """base: tetraspine-ntrt
name: my-fitted-spine
ground_friction: 0.7
rod_materials:
  rod: {friction: 0.8, density_kg_per_cm3: 0.012}
string_materials:
  outer: {stiffness_n_per_m: 1500, damping_n_s_per_m: 12}
  inner: {damping_n_s_per_m: 12}
"""


def _trial(tmp_path: Path, name: str, robot: str, engine: str, *extra: str) -> tuple[dict, np.ndarray]:
    rec = tmp_path / f"{name}-{engine}.npz"
    args = ["trial", robot, "--random-seed", "4", "--duration", "0.3", "--engine", engine, "--record", str(rec),
            "--json", *extra]
    assert main(args) in (0, 1)
    with np.load(rec) as z:
        return json.loads(str(z["trial_config_json"])), z["poses"]


@pytest.mark.parametrize("engine", ["bullet", "mujoco"])
def test_profile_is_the_spec_file_with_its_constants(tmp_path, engine, capsys):
    (tmp_path / "p.yaml").write_text(PROFILE)
    (tmp_path / "spec.yaml").write_text(SPEC)
    cfg, profiled = _trial(tmp_path, "profiled", "tetraspine-ntrt", engine, "--profile", str(tmp_path / "p.yaml"))
    _, spec = _trial(tmp_path, "spec", str(tmp_path / "spec.yaml"), engine)
    _, plain = _trial(tmp_path, "plain", "tetraspine-ntrt", engine)
    assert np.array_equal(profiled, spec)  # the same bits
    assert not np.allclose(profiled[-1], plain[-1])  # and the constants did change the motion
    assert cfg["profile"]["string_stiffness_n_per_m.outer"] == 1500.0
    assert cfg["profile_hash"] == profile_hash(load_profile(tmp_path / "p.yaml"))


@pytest.mark.parametrize(("text", "message"), [
    ("constants: {ground_friction: 5}",
     "profile constant ground_friction is outside its plausible range; received 5; expected a number in [0.1, 1.5]"),
    ("constants: {string_stiffness_n_per_m.outer: 10}", "received 10; expected a number in [100, 1e+06]"),
    ("constants: {friction: 0.5}", "unknown profile constant; received 'friction'; expected one of"),
    ("constants: {string_stiffness_n_per_m.tendon: 900}",
     "profile constant string_stiffness_n_per_m.tendon names a tag the robot lacks; received 'tendon'"),
    ("friction: 0.5", "is not a profile; received ['friction']; expected keys constants"),
])
def test_bad_profile_refused_in_one_line(tmp_path, capsys, text, message):
    (tmp_path / "bad.yaml").write_text(text)
    assert main(["trial", "tetraspine-ntrt", "--random-seed", "1", "--duration", "0.05", "--profile",
                 str(tmp_path / "bad.yaml")]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err


def test_profile_engine_option_twice_refused():
    with pytest.raises(ValueError, match=r"set by both the profile and engine_options; received \['solref_time_s'\]"):
        TrialConfig(engine="mujoco", engine_options={"solref_time_s": 0.01}, profile={"mujoco.solref_time_s": 0.02})


def test_calibration_key_holds_the_profile_hash():
    plain = CalibrationSettings()
    fitted = CalibrationSettings(profile=(("ground_friction", 0.7),))
    other = CalibrationSettings(profile=(("ground_friction", 0.8),))
    assert len({plain.key(), fitted.key(), other.key()}) == 3
    # without a profile the key names no profile: the settings and the judge it was made against (Bullet at
    # 0.25 ms), as before profiles existed
    from spinefarm.protocol.run import json_hash
    assert plain.key() == json_hash({"gaits": 40, "search_trials": 40, "bests": 10, "duration_s": 5.0,
                                     "settle_s": 1.0, "controller": None, "reference": ["bullet", 0.00025]})


def test_search_carries_the_profile_to_its_workers(tmp_path):
    from spinefarm.storage.hdf5_reader import read_run
    from spinefarm.worker.trial.simulation import simulate

    (tmp_path / "p.yaml").write_text(PROFILE)
    run = tmp_path / "run.h5"
    r = subprocess.run([sys.executable, "-m", "spinefarm", "search", "tetraspine-ntrt", "--engine", "mujoco",
                        "--trials", "2", "--workers", "1", "--duration", "0.2", "--out", str(run), "--api-port", "-1",
                        "--quiet", "--profile", str(tmp_path / "p.yaml")], cwd=ROOT, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    meta, rows = read_run(run)
    assert meta.trial_config["profile_hash"] == profile_hash(load_profile(tmp_path / "p.yaml"))
    cfg = TrialConfig.from_dict(meta.trial_config)
    unit, seed, stored = np.array(rows["params_unit"][0]), int(rows["seed"][0]), float(rows["distance_m"][0])
    again = simulate(meta.morphology_spec, unit, cfg, seed).result
    bare = simulate(meta.morphology_spec, unit, dataclasses.replace(cfg, profile={}), seed).result
    assert again.distance_m == stored != bare.distance_m  # the worker ran with the profile


def test_replay_takes_the_profile(tmp_path, capsys):
    (tmp_path / "p.yaml").write_text(PROFILE)
    out = []
    for extra in ([], ["--profile", str(tmp_path / "p.yaml")]):
        assert main(["replay", "tetraspine-ntrt", "--duration", "0.3", "--json", *extra]) == 0
        out.append(json.loads(capsys.readouterr().out)["ntrt_distance_cm"])
    assert out[0] != out[1]


def test_search_refuses_a_profile_of_another_robot_before_writing(tmp_path):
    (tmp_path / "p.yaml").write_text("constants: {string_stiffness_n_per_m.tendon: 900}\n")
    run = tmp_path / "run.h5"
    r = subprocess.run([sys.executable, "-m", "spinefarm", "search", "tetraspine-ntrt", "--engine", "mujoco",
                        "--trials", "2", "--workers", "1", "--duration", "0.2", "--out", str(run), "--api-port", "-1",
                        "--quiet", "--profile", str(tmp_path / "p.yaml")], cwd=ROOT, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 2 and not run.exists()
    assert "names a tag the robot lacks; received 'tendon'; expected one of ['inner', 'outer']" in r.stderr
