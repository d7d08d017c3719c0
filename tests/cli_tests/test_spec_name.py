"""`spinefarm spec NAME` prints a built-in under a name of its own, so a robot derived from it is told apart."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from spinefarm.cli.main import main
from spinefarm.cli.service_commands import default_run_id, robot_name
from spinefarm.robot.morphology.registry import load_morphology

ROOT = Path(__file__).resolve().parents[2]


def spec(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "spinefarm", "spec", *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=60)


def test_a_derived_spec_has_a_name_of_its_own(tmp_path: Path):
    r = spec("tetraspine")
    assert r.returncode == 0, r.stderr
    path = tmp_path / "my_spine.yaml"
    path.write_text(r.stdout)
    mine, builtin = load_morphology(str(path)), load_morphology("tetraspine")
    assert mine.name == "my-tetraspine" != builtin.name
    assert mine.structure.n_segments == builtin.structure.n_segments
    assert len(mine.structure.strings) == len(builtin.structure.strings)
    assert default_run_id(robot_name(str(path))).startswith("my-tetraspine-")


def test_a_chosen_name_and_a_derived_base(tmp_path: Path):
    r = spec("tetraspine-ntrt", "--name", "short-spine")
    path = tmp_path / "short.yaml"
    path.write_text(r.stdout)
    assert r.stdout.count("name: short-spine") == 1 and "name: tetraspine-ntrt" not in r.stdout
    assert load_morphology(str(path)).structure.n_segments == 3


def test_bad_names_are_refused(capsys):
    assert main(["spec", "tetraspine", "--name", "tetraspine"]) != 0
    assert "--name must differ from the built-in's" in capsys.readouterr().err
    assert main(["spec", "tetraspine", "--name", "two words"]) != 0
    err = capsys.readouterr().err
    assert "received 'two words'" in err and len(err.strip().splitlines()) == 1
