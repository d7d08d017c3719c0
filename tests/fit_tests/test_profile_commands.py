"""`accuracy --profile` and `calibrate --profile`: the profile changes their figures exactly as the same constants
written into a spec file (`base: tetraspine-ntrt` plus the materials) do, and the figures differ without it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from .test_profile import PROFILE, ROOT, SPEC

TINY_CALIBRATION = ("--gaits", "3", "--search-trials", "2", "--bests", "1", "--duration", "0.4", "--settle", "0.2",
                    "--jobs", "1", "--json")


def _spinefarm(tmp_path: Path, *args: str) -> dict:
    env = {**os.environ, "SPINEFARM_CACHE_DIR": str(tmp_path / "cache")}
    r = subprocess.run([sys.executable, "-m", "spinefarm", *args], cwd=ROOT, capture_output=True, text=True,
                       timeout=600, env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


def _files(tmp_path: Path) -> tuple[str, str]:
    (tmp_path / "p.yaml").write_text(PROFILE)
    (tmp_path / "spec.yaml").write_text(SPEC)
    return str(tmp_path / "p.yaml"), str(tmp_path / "spec.yaml")


@pytest.mark.slow  # three accuracy sweeps: 115 s on the shared machine
def test_accuracy_profile_is_the_spec_file(tmp_path):
    profile, spec = _files(tmp_path)
    common = ("--quick", "--seeds", "1", "--duration", "0.2", "--jobs", "1", "--engine", "mujoco", "--json")
    out = {name: _spinefarm(tmp_path, "accuracy", robot, *common, "--out", str(tmp_path / name), *extra)
           for name, robot, extra in (("profiled", "tetraspine-ntrt", ("--profile", profile)),
                                      ("spec", spec, ()), ("plain", "tetraspine-ntrt", ()))}

    def figures(report: dict) -> tuple:
        return ([r["distance_m"] for r in report["reference"]],
                [(r["label"], r["distance_errors"]) for r in report["table"]])

    assert figures(out["profiled"]) == figures(out["spec"])
    assert out["profiled"]["reference"][0]["distance_m"] != out["plain"]["reference"][0]["distance_m"]


@pytest.mark.slow  # three calibrations in two tiers: 81 s on the shared machine
def test_calibrate_profile_is_the_spec_file(tmp_path):
    profile, spec = _files(tmp_path)
    profiled = _spinefarm(tmp_path, "calibrate", "tetraspine-ntrt", *TINY_CALIBRATION, "--profile", profile)
    written = _spinefarm(tmp_path, "calibrate", spec, *TINY_CALIBRATION)
    plain = _spinefarm(tmp_path, "calibrate", "tetraspine-ntrt", *TINY_CALIBRATION)
    assert profiled["distance_m"] == written["distance_m"]
    assert profiled["distance_m"]["mujoco"] != plain["distance_m"]["mujoco"]
    assert profiled["distance_m"]["bullet"] != plain["distance_m"]["bullet"]
    assert profiled["profile_hash"] and not written["profile_hash"] and profiled["key"] != plain["key"]
