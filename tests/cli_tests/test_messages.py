"""Messages a newcomer meets, asserted by their text, and their advice followed to see that it works."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from tests.coordinator_tests.procs import ROOT

pytestmark = pytest.mark.integration

SMALL = ("--gaits", "4", "--search-trials", "2", "--bests", "1", "--duration", "0.2", "--settle", "0.1")


def spinefarm(*args: str, cwd, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "spinefarm", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=600, env={**os.environ, "PYTHONPATH": str(ROOT), **(env or {})})


def error_line(r: subprocess.CompletedProcess) -> str:
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr[-2000:]
    lines = [ln for ln in r.stderr.splitlines() if "error:" in ln]
    assert len(lines) == 1, r.stderr
    return lines[0]


def test_overlapping_segments_are_named_as_such_not_as_a_pretension_that_contradicts_itself(tmp_path):
    (tmp_path / "stacked.yaml").write_text("base: tetraspine-ntrt\nname: stacked\nsegments:\n  transforms:\n"
                                           "    - translate: [0, 2, 0]\n")
    line = error_line(spinefarm("trial", "stacked.yaml", "--duration", "0.1", cwd=tmp_path))
    assert ("string 0 (outer, nodes 0 -> 4) has no length at the start: its ends coincide, so two segments "
            "overlap; move them apart in the spec (segments: transforms)") in line
    assert "received '0 cm'; expected a start length of at least 0.001 cm" in line and "pretension" not in line
    check = spinefarm("check", "stacked.yaml", cwd=tmp_path)
    assert check.returncode == 1 and "FAIL builds: string 0 (outer, nodes 0 -> 4) has no length" in check.stdout
    # the advice: segments apart again (the built-in's spacing, 28.575 cm) and the check passes
    (tmp_path / "stacked.yaml").write_text("base: tetraspine-ntrt\nname: stacked\nsegments:\n  transforms:\n"
                                           "    - translate: [0, 2, \"100 - (i + 1) * 28.575\"]\n")
    assert spinefarm("check", "stacked.yaml", cwd=tmp_path).returncode == 0


def test_a_missing_spec_file_is_called_missing_and_the_advice_makes_one(tmp_path):
    line = error_line(spinefarm("trial", "nosuch.yaml", "--duration", "0.1", cwd=tmp_path))
    assert "spec file not found; received 'nosuch.yaml'; expected an existing .yaml spec file (there is none at " \
           f"{tmp_path.resolve() / 'nosuch.yaml'}), or a built-in name: octahedral-complex, " in line
    assert "unknown morphology" not in line and "`spinefarm spec NAME > FILE.yaml` starts a new one" in line
    # a name that is no file is still an unknown morphology
    assert "unknown morphology; received 'nosuch'" in error_line(spinefarm("trial", "nosuch", cwd=tmp_path))
    spec = spinefarm("spec", "tetraspine-ntrt", "--name", "nosuch", cwd=tmp_path)
    (tmp_path / "nosuch.yaml").write_text(spec.stdout)
    assert spinefarm("check", "nosuch.yaml", cwd=tmp_path).returncode == 0


def test_calibrate_takes_the_dt_its_advice_names_and_a_stable_step_by_default(tmp_path):
    env = {"SPINEFARM_CACHE_DIR": str(tmp_path / "cache")}
    line = error_line(spinefarm("calibrate", "tetraspine-hardware", "--dt", "0.001", *SMALL, cwd=tmp_path, env=env))
    assert "dt_s is unstable for tetraspine-hardware" in line and "set auto_dt (--dt auto)" in line
    assert not (tmp_path / "cache").exists()  # refused before the first trial
    auto = spinefarm("calibrate", "tetraspine-hardware", "--dt", "auto", *SMALL, "--json", cwd=tmp_path, env=env)
    assert auto.returncode == 0, auto.stderr[-2000:]
    result = json.loads(auto.stdout.strip().splitlines()[-1])
    assert result["settings"]["auto_dt"] is True and result["decision"] in ("mujoco", "bullet")
    assert "step: " not in auto.stderr  # a step was asked for: none is chosen
    default = spinefarm("calibrate", "tetraspine-hardware", *SMALL, cwd=tmp_path, env=env)
    assert default.returncode == 0, default.stderr[-2000:]
    assert "step: 0.254 ms for tetraspine-hardware (the default step, mujoco's 1 ms, bullet's 1 ms, is above its " \
           "stable limit of 0.509 ms; --dt sets another)" in default.stderr
    assert "[cached]" in default.stdout  # the same calibration as --dt auto's
