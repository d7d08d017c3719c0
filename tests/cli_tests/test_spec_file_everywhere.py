"""A robot from a spec file goes wherever a built-in goes: check, trial, render and accuracy on both engines, a
search, a stored trial re-run and drawn, an export, and NTRT's parameters replayed on it. Short and real."""

from __future__ import annotations

import csv
import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from spinefarm.cli.main import main
from spinefarm.worker.tools.replay import PUBLISHED
from tests.coordinator_tests.procs import ROOT

ROBOT = "my-spine"
ENGINES = ("bullet", "mujoco")


@pytest.fixture(scope="module")
def spec(tmp_path_factory) -> Path:
    """NTRT's three-segment Tetraspine under a name of its own, as `spinefarm spec` starts a user's robot."""
    path = tmp_path_factory.mktemp("robot") / f"{ROBOT}.yaml"
    out = subprocess.run([sys.executable, "-m", "spinefarm", "spec", "tetraspine-ntrt", "--name", ROBOT], cwd=ROOT,
                         capture_output=True, text=True, check=True).stdout
    path.write_text(out)
    return path


def _json(capsys) -> dict:
    return json.loads(capsys.readouterr().out)


def test_check_trial_render_and_accuracy_on_both_engines(spec, tmp_path, capsys):
    assert main(["check", str(spec), "--json"]) == 0
    assert _json(capsys)["passed"] is True
    for engine in ENGINES:
        assert main(["trial", str(spec), "--random-seed", "1", "--duration", "0.2", "--engine", engine, "--json"]) == 0
        trial = _json(capsys)
        assert trial["morphology"] == ROBOT and trial["status"] == "complete" and trial["extras"]["engine"] == engine
        strip = tmp_path / f"strip-{engine}.png"
        assert main(["render", str(spec), "--duration", "0.2", "--frames", "2", "--engine", engine,
                     "--out", str(strip)]) == 0
        assert strip.stat().st_size > 5_000
        capsys.readouterr()
        assert main(["accuracy", str(spec), "--quick", "--seeds", "1", "--duration", "0.2", "--jobs", "1",
                     "--engine", engine, "--out", str(tmp_path / f"acc-{engine}"), "--json"]) == 0
        report = _json(capsys)
        assert report["engine"] == engine and math.isfinite(report["default_distance_error"])
        assert all(st == "complete" for row in report["table"] for st in row["statuses"])


def test_search_then_rerun_draw_and_export_a_stored_trial(spec, tmp_path, capsys):
    run = tmp_path / "run.h5"
    r = subprocess.run([sys.executable, "-m", "spinefarm", "search", str(spec), "--engine", "mujoco", "--trials", "4",
                        "--workers", "1", "--duration", "0.2", "--out", str(run), "--api-port", "-1", "--quiet"],
                       cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert main(["trial", "--run", str(run), "--engine", "bullet", "--json"]) == 0
    rerun = _json(capsys)
    assert rerun["morphology"] == ROBOT and rerun["extras"]["engine"] == "bullet" and "rerun_of" in rerun
    strip = tmp_path / "best.png"
    assert main(["render", "--run", str(run), "--frames", "2", "--out", str(strip)]) == 0
    assert strip.stat().st_size > 5_000
    table = tmp_path / "trials.csv"
    capsys.readouterr()
    assert main(["export", str(run), "--best", "2", "--csv", str(table)]) == 0
    assert capsys.readouterr().out.splitlines()[2].split()[0] == "2"  # the two best printed
    with table.open() as fh:
        assert len(list(csv.DictReader(fh))) == 4  # every trial written


def test_ntrt_parameters_replay_on_it_and_run_from_their_gait_file(spec, tmp_path, capsys):
    gait = tmp_path / "ntrt.json"
    assert main(["replay", str(PUBLISHED["tetraspine-ntrt"]), "--morphology", str(spec), "--duration", "0.1",
                 "--json", "--gait", str(gait)]) == 0
    out = _json(capsys)
    assert out["morphology"] == ROBOT and out["sim_time_s"] == pytest.approx(0.1)
    assert json.loads(gait.read_text())["morphology"] == ROBOT
    assert main(["trial", str(spec), "--params", str(gait), "--duration", "0.1", "--json"]) == 0
    assert _json(capsys)["status"] == "complete"
