"""Bullet's constraint solver as an engine option: NTRT's current code (and so its recordings) solves contacts
with Bullet's MLCP solver and the Dantzig LCP solver, its 2014 code with sequential impulse (ntrt-spec.md §1).
The expectations are pybullet's own report of the solver it switched to, and gravity's on a robot at rest."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from spinefarm.protocol.errors import ConfigError
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.tools.replay import read_parameter_set, unit_params
from spinefarm.worker.trial.simulation import simulate

RUN = Path(__file__).parent / "data" / "ntrt-recordings" / "TetraSpine" / "random-00"


def _trial(options: dict) -> tuple[float, np.ndarray]:
    morph = load_morphology("tetraspine-ntrt2026")
    cfg = TrialConfig(duration_s=0.3, dt_s=0.001, motor_model="ntrt2026", controller="ntrt", engine="bullet",
                      engine_options={"friction_anchor": False, **options}, record_every_s=0.01)
    out = simulate(morph, unit_params(morph, read_parameter_set(RUN)), cfg, 0)
    return out.result.ntrt_distance_cm, out.trajectory.arrays()["poses"][..., :3]


def test_the_mlcp_dantzig_solver_is_the_one_bullet_runs(capfd):
    default_cm, _ = _trial({})
    assert "MLCP + Dantzig" not in capfd.readouterr().out
    mlcp_cm, pos_cm = _trial({"constraint_solver": "mlcp_dantzig"})
    assert "MLCP + Dantzig" in capfd.readouterr().out  # pybullet's own message on switching
    assert mlcp_cm != default_cm
    # the robot lands and stays up: no segment's centre falls through the ground (top at 0.5 cm) under it
    assert np.isfinite(pos_cm).all() and pos_cm[..., 1].min() > 0.5


def test_an_unknown_solver_is_refused():
    with pytest.raises(ConfigError, match="constraint_solver"):
        TrialConfig(engine="bullet", engine_options={"constraint_solver": "lemke"})
