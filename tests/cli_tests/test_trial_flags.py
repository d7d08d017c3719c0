"""`trial` takes its robot from a gait file; a bad number flag of `trial` or `search` is named as typed."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.cli_tests.test_errors import one_line_error, run

ROOT = Path(__file__).resolve().parents[2]
GAIT = ROOT / "examples" / "gaits" / "tetraspine.json"


def _trial_json(*args: str) -> tuple[dict, str]:
    r = run("trial", *args, "--duration", "0.3", "--json", timeout=90)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout), r.stderr


def test_a_gait_file_names_the_robot_it_was_found_on():
    named, _ = _trial_json("tetraspine", "--params", str(GAIT))
    taken, said = _trial_json("--params", str(GAIT))
    assert "robot: tetraspine" in said
    assert taken["morphology"] == "tetraspine"
    assert taken["distance_m"] == named["distance_m"]  # the same robot, gait and seed: the same trial


def test_a_gait_file_may_name_a_users_spec_beside_it(tmp_path):
    spec = run("spec", "tetraspine-ntrt", "--name", "my-spine", timeout=60)
    assert spec.returncode == 0, spec.stderr
    (tmp_path / "my-spine.yaml").write_text(spec.stdout)
    gait = json.loads(GAIT.read_text())
    gait["morphology"] = "my-spine.yaml"  # relative to the gait file, not to where trial runs
    (tmp_path / "gait.json").write_text(json.dumps(gait))
    taken, said = _trial_json("--params", str(tmp_path / "gait.json"))
    assert taken["morphology"] == "my-spine"
    assert "my-spine.yaml" in said


def test_a_gait_file_naming_no_robot_is_refused_in_one_line(tmp_path):
    gait = json.loads(GAIT.read_text())
    del gait["morphology"]
    (tmp_path / "gait.json").write_text(json.dumps(gait))
    one_line_error(run("trial", "--params", str(tmp_path / "gait.json"), timeout=60), "names none",
                   "gait.json", "\"morphology\"")


# (command, flag, value, as received, expected range): the ranges TrialConfig and the run's settings hold
BAD_FLAGS = [
    ("trial", "--duration", "-1", "-1.0", "(0, 3600]"),
    ("trial", "--dt", "0", "0.0", "[1e-06, 0.02]"),
    ("trial", "--settle", "-1", "-1.0", "[0, 60]"),
    ("trial", "--cpg-step", "1", "1.0", "[0, 0.1]"),
    ("trial", "--record-every", "0", "0.0", "[1e-06, 10]"),
    ("search", "--settle", "61", "61.0", "[0, 60]"),
    ("search", "--verify-dt", "1", "1.0", "[1e-06, 0.02]"),
    ("search", "--top-k", "0", "0", "at least 1"),
    ("search", "--startup-trials", "-1", "-1", "at least 0"),
    ("search", "--batch", "0", "0", "[1, 4096]"),
    ("search", "--batch", "5000", "5000", "[1, 4096]"),
    ("search", "--sigma", "2", "2.0", "(0, 1]"),
    ("search", "--lease", "0", "0.0", "(0, inf]"),
    ("search", "--audit", "2", "2.0", "[0, 1]"),
]


@pytest.mark.parametrize(("command", "flag", "value", "received", "expected"), BAD_FLAGS)
def test_a_bad_number_flag_is_named_with_its_value_and_range(command, flag, value, received, expected, tmp_path):
    out = ("--out", str(tmp_path / "r.h5"), "--workers", "0", "--api-port", "-1") if command == "search" else ()
    r = run(command, "tetraspine", flag, value, *out, timeout=60)
    one_line_error(r, f"error: {flag} out of range", f"received {received};", expected)
    assert not (tmp_path / "r.h5").exists()


def test_a_gait_file_may_record_the_spec_itself(tmp_path):
    from spinefarm.robot.morphology.registry import load_morphology

    spec = {**load_morphology("tetraspine-ntrt").to_dict(), "name": "recorded-spine"}
    gait = {**json.loads(GAIT.read_text()), "morphology": "tetraspine", "morphology_spec": spec}
    (tmp_path / "gait.json").write_text(json.dumps(gait))
    taken, said = _trial_json("--params", str(tmp_path / "gait.json"))
    assert taken["morphology"] == "recorded-spine"  # the recorded spec, exact, over the name beside it
    assert "the spec it records (recorded-spine)" in said


def test_a_gait_exported_from_a_spec_files_run_runs_alone(tmp_path):
    """A user's robot is as good as a built-in: its run's gait file carries the spec, no robot argument needed."""
    spec = run("spec", "tetraspine-ntrt", "--name", "exported-spine", timeout=60)
    (tmp_path / "exported-spine.yaml").write_text(spec.stdout)
    out = tmp_path / "r.h5"
    r = run("search", str(tmp_path / "exported-spine.yaml"), "--trials", "2", "--workers", "1", "--duration", "0.2",
            "--engine", "bullet", "--no-verify", "--api-port", "-1", "--quiet", "--out", str(out), timeout=180)
    assert r.returncode == 0, r.stderr
    (tmp_path / "exported-spine.yaml").unlink()  # the gait file alone must say which robot
    assert run("export", str(out), "--gait", str(tmp_path / "best.json"), timeout=60).returncode == 0
    taken, said = _trial_json("--params", str(tmp_path / "best.json"))
    assert taken["morphology"] == "exported-spine" and "the spec it records" in said
