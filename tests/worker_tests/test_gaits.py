"""Every shipped gait (examples/gaits/<morphology>.json, and those of a robust search in examples/gaits/robust/)
loads as a --params file and runs for 1 s."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from spinefarm.cli.sim_commands import load_params_file
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.spaces import param_space
from spinefarm.worker.trial.simulation import TrialConfig, simulate

ROOT = Path(__file__).resolve().parents[2] / "examples" / "gaits"
GAITS = sorted(ROOT.rglob("*.json"))


def test_gaits_are_shipped():
    assert GAITS, "examples/gaits holds no gait"


@pytest.mark.parametrize("path", GAITS, ids=[p.relative_to(ROOT).with_suffix("").as_posix() for p in GAITS])
def test_a_shipped_gait_loads_and_runs_for_one_second(path):
    params, controller = load_params_file(path)
    record = json.loads(path.read_text())
    assert record["morphology"] == path.stem and controller
    morph = load_morphology(path.stem)
    assert list(params) == param_space(morph, controller).names
    r = simulate(morph, params, TrialConfig(duration_s=1.0, controller=controller)).result
    assert r.ok and r.distance_m > 0
