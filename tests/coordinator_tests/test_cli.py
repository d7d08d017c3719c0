"""The service sub-commands as a user meets them: exit codes and messages."""

from __future__ import annotations

import subprocess
import sys

import pytest

from tests.coordinator_tests.procs import ROOT


def run(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "spinefarm", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=timeout)


def test_help_lists_the_service_commands():
    out = run("--help").stdout
    for name in ("search", "coordinator", "worker", "api", "export"):
        assert name in out


@pytest.mark.parametrize(("args", "message"), [
    (("export", "missing.h5", "--best", "3"), "run file does not exist"),
    (("export", "tests", "--best", "3"), "a folder is no run file"),
    (("search", "no-such-robot", "--trials", "5", "--workers", "0", "--api-port", "-1"), "no-such-robot"),
    (("search", "sphere:3", "--trials", "0", "--workers", "0", "--api-port", "-1"), "trials out of range"),
    (("search", "sphere:3", "--objective", "fame", "--workers", "0", "--api-port", "-1"), "unknown objective"),
    (("search", "sphere:3", "--objective", "cot:fast", "--workers", "0", "--api-port", "-1"), "'cot:fast'"),
    (("search", "sphere:3", "--sampler", "annealing", "--workers", "0", "--api-port", "-1"), "unknown sampler"),
    (("search", "--resume", "missing.h5", "--workers", "0"), "cannot resume"),
    (("search", "--workers", "0"), "no morphology given"),
    (("worker", "--zenoh-config", "missing.json5"), "cannot read Zenoh config"),
])
def test_bad_input_is_a_clear_error_with_exit_code_2(tmp_path, args, message):
    r = run(*args)
    assert r.returncode == 2, r.stderr
    assert message in r.stderr


def test_a_short_search_then_export(tmp_path):
    out = tmp_path / "run.h5"
    r = run("search", "sphere:3", "--trials", "50", "--workers", "1", "--out", str(out), "--api-port", "-1",
            "--seed", "5")
    assert r.returncode == 0, r.stderr
    assert "best trial" in r.stdout and str(out) in r.stdout and "50/50 parameter sets" in r.stderr
    again = run("search", "sphere:3", "--trials", "50", "--workers", "1", "--out", str(out), "--api-port", "-1")
    assert again.returncode == 2 and "already exists" in again.stderr and "--overwrite" in again.stderr
    replaced = run("search", "sphere:3", "--trials", "20", "--workers", "1", "--out", str(out), "--api-port", "-1",
                   "--overwrite")
    assert replaced.returncode == 0 and "20/20 parameter sets" in replaced.stderr
    assert run("search", "sphere:3", "--trials", "50", "--workers", "1", "--out", str(out), "--api-port", "-1",
               "--overwrite", "--seed", "5").returncode == 0
    csv_path = tmp_path / "run.csv"
    assert run("export", str(out), "--csv", str(csv_path)).returncode == 0
    lines = csv_path.read_text().splitlines()
    assert len(lines) == 51 and lines[0].endswith("x0,x1,x2")
    best = run("export", str(out), "--best", "3").stdout.splitlines()
    assert best[0].split()[:2] == ["rank", "trial"] and len([ln for ln in best if ln[:4].strip().isdigit()]) == 3
    gait = tmp_path / "gait.json"
    assert run("export", str(out), "--gait", str(gait)).returncode == 0
    import json

    from spinefarm.storage.hdf5 import Hdf5Storage

    g, top = json.loads(gait.read_text()), Hdf5Storage.open_read(out).best(1)[0]
    assert g["source"]["trial_id"] == top.trial_id and list(g["params"].values()) == list(top.params)
    assert list(g["params"]) == ["x0", "x1", "x2"]


def test_a_cot_objective_search_reports_the_speed_and_cost_it_trades(tmp_path):
    out = tmp_path / "cot.h5"
    r = run("search", "sphere:3", "--objective", "cot:5", "--trials", "30", "--workers", "1", "--out", str(out),
            "--api-port", "-1")
    assert r.returncode == 0, r.stderr
    assert "30/30 parameter sets, " in r.stderr and " cm/s, COT " in r.stderr  # the progress line names both
    assert "cot:5 " in r.stdout  # the report names the objective beside the score's parts
