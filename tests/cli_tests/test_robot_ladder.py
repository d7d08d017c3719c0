"""A robot's screening ladder (robot.morphology.specladder, docs/morphology-format.md "The screening ladder"):
what `--engine auto` screens with on MuJoCo when no `--rungs` are given. A user's spec file carries its own or
takes its base's, as a built-in does; a typed `--rungs` or `--eta` wins; bad values are refused in one line.
The calibration is a shipped result (no child runs): what is checked is the ladder chosen with it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from spinefarm.cli import engine_auto
from spinefarm.cli.main import build_parser, main
from spinefarm.protocol.errors import MorphologySpecError
from spinefarm.robot.morphology.registry import load_ladder, load_morphology
from spinefarm.worker.tools import shipped_calibration

LADDER = "ladder:\n  rungs: [2/30, 5/30, 1]\n  eta: 3\n"


def _spec(folder: Path, name: str, body: str, base: str = "tetraspine", named: bool = True) -> Path:
    path = folder / name
    path.write_text(f"base: {base}\n" + (f"name: {path.stem}\n" if named else "") + body)
    return path


@pytest.fixture
def mujoco(tmp_path, monkeypatch) -> None:
    """Every calibration decides MuJoCo (the tetrahedral complex's shipped result; none shipped is looked up)."""
    result = json.loads(shipped_calibration.shipped_path("tetrahedral-complex").read_text())
    monkeypatch.setattr(shipped_calibration, "SHIPPED_DIR", tmp_path / "none-shipped")
    monkeypatch.setattr(engine_auto, "calibrate_in_child", lambda *a, **kw: (dict(result), True))


def _choose(*argv: str):
    args = build_parser().parse_args(["search", *argv])
    return args, engine_auto.choose_engine(args)


def test_a_spec_files_ladder_is_its_fractions_of_the_trial_at_its_eta(tmp_path, mujoco):
    path = _spec(tmp_path, "mine.yaml", LADDER)
    args, choice = _choose(str(path))  # the Tetraspine's 30 s trial
    assert (args.rungs, args.eta) == ("2,5,30", 3)
    assert (choice.rungs_added, choice.eta_added) == ("2,5,30", 3)
    assert "rungs 2,5,30 eta 3 (the robot's ladder, mine.yaml)" in choice.describe()
    args, _ = _choose(str(path), "--duration", "12")
    assert (args.rungs, args.eta) == ("0.8,2,12", 3)  # 12 * 2/30, 12 * 5/30, 12


def test_a_ladder_with_its_measurement_says_it_is_measured(tmp_path, mujoco):
    path = _spec(tmp_path, "measured.yaml", LADDER + "  source: python bench/ladder.py --gaits 27\n")
    _, choice = _choose(str(path))
    assert "eta 3 (the robot's measured ladder, measured.yaml)" in choice.describe()


def test_a_file_without_a_ladder_takes_its_bases_and_else_the_default(tmp_path, mujoco):
    parent = _spec(tmp_path, "parent.yaml", LADDER)
    child = _spec(tmp_path, "child.yaml", "duration_s: 15\n", base="parent.yaml")
    assert (load_ladder(str(child)).rungs(15.0), load_ladder(str(child)).eta) == ("1,2.5,15", 3)
    args, _ = _choose(str(child))
    assert (args.rungs, args.eta) == ("1,2.5,15", 3)
    plain = _spec(tmp_path, "plain.yaml", "")
    args, choice = _choose(str(plain))
    assert (args.rungs, args.eta) == ("5,10,30", 4)  # a sixth, a third, the whole, eta 4
    assert "(the default ladder: a sixth, a third and the whole trial)" in choice.describe()
    assert parent.exists()


def test_a_files_own_ladder_replaces_its_bases_whole(tmp_path):
    # the tetrahedral complex's is measured (its block names the command); a file's own block is not that one
    path = _spec(tmp_path, "own.yaml", "ladder:\n  rungs: [1/2, 1]\n  eta: 2\n", base="tetrahedral-complex")
    assert load_ladder("tetrahedral-complex").source.startswith("python bench/ladder.py")
    ladder = load_ladder(str(path))
    assert (ladder.rungs(30.0), ladder.eta, ladder.source, ladder.reason) == (
        "15,30", 2, "", "the robot's ladder, own.yaml")


def test_a_typed_rungs_or_eta_wins(tmp_path, mujoco):
    from spinefarm.cli.run_setup import search_settings
    from spinefarm.protocol.settings import JudgePolicy

    path = _spec(tmp_path, "mine.yaml", LADDER)
    args, choice = _choose(str(path), "--eta", "5")
    assert (args.rungs, args.eta, choice.eta_added) == ("2,5,30", 5, 5)
    assert "; --eta 5 given)" in choice.describe()
    args, choice = _choose(str(path), "--rungs", "1,3")
    assert (args.rungs, args.eta, choice.rungs_added) == ("1,3", None, None)
    # --rungs without --eta: eta 4, as for every --rungs
    assert search_settings(args, (1.0, 3.0), 60.0, JudgePolicy(), choice).eta == 4


@pytest.mark.parametrize(("block", "field", "received"), [
    ("rungs: [0.5, 0.2, 1]\n  eta: 3", "ladder.rungs", "[0.5, 0.2, 1.0]"),   # not increasing
    ("rungs: [0.2, 0.5]\n  eta: 3", "ladder.rungs", "[0.2, 0.5]"),           # not ending at the whole trial
    ("rungs: [0, 1]\n  eta: 3", "ladder.rungs", "[0.0, 1.0]"),               # a rung of no length
    ("rungs: [1/6, 1]\n  eta: 1", "ladder.eta", "1"),
    ("rungs: [1/6, 1]\n  eta: 2.5", "ladder.eta", "2.5"),
])
def test_a_bad_ladder_is_refused_in_one_line_naming_what_and_where(tmp_path, capsys, block, field, received):
    path = _spec(tmp_path, "bad.yaml", f"ladder:\n  {block}\n")
    with pytest.raises(MorphologySpecError) as caught:
        load_morphology(str(path))
    text = str(caught.value)
    assert f"field {field}" in text and f"received {received}" in text and "expected" in text
    assert "\n" not in text and "bad.yaml, line " in text
    out = tmp_path / "run.h5"
    assert main(["search", str(path), "--out", str(out), "--trials", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"field {field}" in err and not out.exists()  # nothing written


def test_an_exported_builtin_carries_the_builtins_ladder(tmp_path, capsys):
    """`spinefarm spec NAME > FILE.yaml`, the way to start a robot of one's own, keeps the built-in's ladder."""
    for name in ("tetrahedral-complex", "tetraspine"):
        assert main(["spec", name]) == 0
        path = tmp_path / f"my-{name}.yaml"
        path.write_text(capsys.readouterr().out)
        mine, builtin = load_ladder(str(path)), load_ladder(name)
        assert (mine.fractions, mine.eta, mine.source) == (builtin.fractions, builtin.eta, builtin.source), name


def _search(robot: str, out: Path) -> str:
    """A real short search (MuJoCo workers over Zenoh, an HDF5 run file), its standard error."""
    import subprocess
    import sys

    from tests.coordinator_tests.procs import ROOT

    r = subprocess.run([sys.executable, "-m", "spinefarm", "search", robot, "--trials", "4", "--duration", "3",
                        "--workers", "2", "--out", str(out), "--api-port", "-1", "--quiet", "--no-verify"],
                       cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    return r.stderr


def test_a_search_of_a_users_file_screens_with_its_ladder_and_stores_it(tmp_path):
    from spinefarm.storage.hdf5_reader import read_run

    # the tetrahedral complex itself, name and all (so its shipped calibration, MuJoCo, answers at once), with a
    # ladder of the file's own
    path = _spec(tmp_path, "mine.yaml", "ladder:\n  rungs: [1/6, 1/2, 1]\n  eta: 2\n", base="tetrahedral-complex",
                 named=False)
    err = _search(str(path), tmp_path / "mine.h5")
    settings = read_run(tmp_path / "mine.h5")[0].settings
    assert ([r.duration_s for r in settings.ladder], settings.eta) == ([0.5, 1.5, 3.0], 2)  # 3 s / 6, 3 s / 2, 3 s
    choice = settings.engine_choice
    assert (choice.rungs_added, choice.eta_added, choice.ladder_reason) == ("0.5,1.5,3", 2, "the robot's ladder, "
                                                                                            "mine.yaml")
    assert "rungs 0.5,1.5,3 eta 2 (the robot's ladder, mine.yaml)" in err and "calibrating" not in err


def test_a_search_of_the_tetrahedral_complex_screens_with_its_measured_ladder(tmp_path):
    from spinefarm.storage.hdf5_reader import read_run

    err = _search("tetrahedral-complex", tmp_path / "tc.h5")
    settings = read_run(tmp_path / "tc.h5")[0].settings
    # docs/performance.md, "Per robot": a sixth, a third and the whole at eta 4, measured on this robot
    assert ([r.duration_s for r in settings.ladder], settings.eta) == ([0.5, 1.0, 3.0], 4)
    assert settings.engine_choice.ladder_reason == "the robot's measured ladder, tetrahedral-complex.yaml"
    assert "rungs 0.5,1,3 eta 4 (the robot's measured ladder, tetrahedral-complex.yaml)" in err


def test_check_shows_a_files_ladder(tmp_path, capsys):
    from tests.worker_tests.test_specfile import GOOD

    path = tmp_path / "chain.yaml"
    path.write_text(GOOD + LADDER)  # a 10 s trial
    main(["check", str(path), "--json"])
    ladder = json.loads(capsys.readouterr().out)["ladder"]
    # 10 * 2/30 and 10 * 5/30 s, to six digits
    assert ladder == {"rungs": "0.666667,1.66667,10", "eta": 3, "reason": "the robot's ladder, chain.yaml"}
