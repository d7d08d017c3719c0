"""A robot whose engine's default step is above its stable limit (the hardware Tetraspine: 0.509 ms against
Bullet's 1 ms, docs/stability.md) runs with the defaults at half that limit, and the step is printed; a typed
--dt is taken as typed. (search and calibrate: tests/coordinator_tests/test_search_dt.py,
tests/cli_tests/test_messages.py.)"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from tests.coordinator_tests.procs import ROOT

pytestmark = pytest.mark.integration

SAID = ("step: 0.254 ms for tetraspine-hardware (the default step, bullet's 1 ms, is above its stable limit of "
        "0.509 ms; --dt sets another)")


def spinefarm(*args: str, cwd) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "spinefarm", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=600, env={**os.environ, "PYTHONPATH": str(ROOT)})


def test_a_trial_of_the_hardware_tetraspine_runs_with_defaults_at_a_stable_step(tmp_path):
    r = spinefarm("trial", "tetraspine-hardware", "--duration", "0.2", "--json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    assert SAID in r.stderr
    result = json.loads(r.stdout.strip().splitlines()[-1])
    assert result["status"] == "complete" and 2.5e-4 < result["extras"]["dt_s"] < 2.6e-4
    typed = spinefarm("trial", "tetraspine-hardware", "--duration", "0.2", "--dt", "0.0002", cwd=tmp_path)
    assert typed.returncode == 0 and "step: " not in typed.stderr and "dt 0.2 ms" in typed.stdout
    # a robot whose default step is stable keeps it, and nothing is said
    ntrt = spinefarm("trial", "tetraspine-ntrt", "--duration", "0.2", cwd=tmp_path)
    assert ntrt.returncode == 0 and "step: " not in ntrt.stderr and "(bullet, dt 1 ms)" in ntrt.stdout


def test_accuracy_of_the_hardware_tetraspine_runs_with_defaults(tmp_path):
    r = spinefarm("accuracy", "tetraspine-hardware", "--quick", "--seeds", "1", "--duration", "0.2", "--out",
                  str(tmp_path / "acc"), "--json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    assert SAID in r.stderr
    table = {row["label"]: row for row in json.loads(r.stdout.strip().splitlines()[-1])["table"]}
    # the settings that name no step run at the stable one; the steps swept stay as named (1 ms is unstable)
    assert table["solver 50 iterations"]["statuses"] == ["complete"]
    assert table["scene: slope 5 deg"]["statuses"] == ["complete"]
    assert table["dt 1 ms (default)"]["statuses"] == ["refused"] and table["dt 0.5 ms"]["statuses"] == ["complete"]
