"""The calibration's reference is the search's judge (Bullet at 0.25 ms, docs/engines.md and `spinefarm search
--help`), not Bullet's default 1 ms; the built-ins' calibrations ship as package data, used when made for the
very model and settings asked for and ignored otherwise. Real trials on both engines."""

from __future__ import annotations

import json

import numpy as np

from spinefarm.cli.main import build_parser
from spinefarm.robot.morphology.registry import builtin_path, load_morphology
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.tools import shipped_calibration
from spinefarm.worker.tools.calibrate import CalibrationSettings, calibrate, calibration
from spinefarm.worker.tools.shipped_calibration import shipped
from spinefarm.worker.trial.simulation import simulate

JUDGE_DT_S = 0.00025  # the judge's documented step (docs/accuracy.md: Bullet within ~1.5 % there)
ROBOT = "tetrahedral-complex"


def test_the_search_judges_at_the_documented_step():
    args = build_parser().parse_args(["search", ROBOT])
    assert args.verify_dt == JUDGE_DT_S


def test_the_reference_runs_at_the_judges_step_not_bullets_default():
    s = CalibrationSettings(gaits=3, search_trials=0, bests=0, duration_s=0.6, settle_s=0.2)
    out = calibrate(ROBOT, s)
    assert out["reference"]["engine"] == "bullet" and out["reference"]["dt_s"] == JUDGE_DT_S
    assert out["tiers"]["bullet"]["dt_s"] == JUDGE_DT_S and out["tiers"]["mujoco"]["dt_s"] == 0.001
    # the figures are those of trials at that step: gait 1 replayed on its own at 0.25 ms and at Bullet's 1 ms
    morph = load_morphology(ROBOT)
    from spinefarm.worker.trial.simulation import random_unit_params

    unit = np.asarray(random_unit_params(morph, 1, None))
    at = {dt: simulate(morph, unit, TrialConfig(duration_s=0.6, settle_s=0.2, engine="bullet", dt_s=dt), 1).result
          .distance_m for dt in (JUDGE_DT_S, 0.001)}
    assert abs(at[JUDGE_DT_S] - at[0.001]) > 1e-5, at  # the steps are told apart on this gait
    assert out["distance_m"]["bullet"][0] == round(at[JUDGE_DT_S], 6)


def test_the_key_names_the_reference_so_calibrations_against_bullets_default_are_not_reused():
    from spinefarm.protocol.run import json_hash

    written_out = {"gaits": 40, "search_trials": 40, "bests": 10, "duration_s": 5.0, "settle_s": 1.0,
                   "controller": None}
    assert CalibrationSettings().key() != json_hash(written_out)  # the key of a calibration against 1 ms
    assert CalibrationSettings().key() == json_hash({**written_out, "reference": ["bullet", JUDGE_DT_S]})
    assert len({CalibrationSettings().key(), CalibrationSettings(gaits=41).key(),
                CalibrationSettings(profile=(("friction", 0.8),)).key()}) == 3


def _ship(tmp_path, monkeypatch, robot: str, settings: CalibrationSettings, decision: str) -> None:
    monkeypatch.setattr(shipped_calibration, "SHIPPED_DIR", tmp_path / "shipped")
    morph = load_morphology(robot)
    path = shipped_calibration.shipped_path(morph.name)
    path.parent.mkdir()
    path.write_text(json.dumps({"robot": morph.name, "spec_hash": morph.spec_hash(), "key": settings.key(),
                                "decision": decision, "distance_m": {"mujoco": [0.3], "bullet": [0.31]}}))


def test_a_shipped_calibration_is_used_and_a_changed_model_is_not(tmp_path, monkeypatch):
    s = CalibrationSettings()
    _ship(tmp_path, monkeypatch, ROBOT, s, "mujoco")
    monkeypatch.setenv("SPINEFARM_CACHE_DIR", str(tmp_path / "cache"))
    result, cached = calibration(ROBOT, s)  # would take many minutes were it computed
    assert cached and result["shipped"] and result["distance_m"]["bullet"] == [0.31]
    assert shipped(ROBOT, CalibrationSettings(gaits=39)) is None  # other settings
    assert shipped(ROBOT, CalibrationSettings(profile=(("friction", 0.8),))) is None  # another profile
    # a user's spec under the same name that differs in one constant: the muscles' stiffness
    text = builtin_path(ROBOT).read_text()
    spec = tmp_path / "stiffer.yaml"
    spec.write_text(text.replace("stiffness_n_per_m: 1000,", "stiffness_n_per_m: 1001,", 1))
    assert spec.read_text() != text and load_morphology(str(spec)).name == ROBOT
    assert shipped(str(spec), s) is None
    same = tmp_path / "same.yaml"  # the very model in a user's file is as good as the built-in
    same.write_text(text)
    assert shipped(str(same), s)["decision"] == "mujoco"


def test_a_damaged_shipped_file_is_ignored(tmp_path, monkeypatch):
    _ship(tmp_path, monkeypatch, ROBOT, CalibrationSettings(), "mujoco")
    shipped_calibration.shipped_path(ROBOT).write_text("{not json")
    assert shipped(ROBOT, CalibrationSettings()) is None
