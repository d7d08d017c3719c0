"""Bullet's constraint solver as an engine option: NTRT's current code (and so its recordings) solves contacts
with Bullet's MLCP solver and the Dantzig LCP solver, its 2014 code with sequential impulse (ntrt-spec.md §1).
The expectations are pybullet's own report of the solver it switched to, and gravity's on a robot at rest."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from spinefarm.protocol.errors import ConfigError
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.tools.replay import read_parameter_set, unit_params
from spinefarm.worker.trial.simulation import simulate

ROOT = Path(__file__).resolve().parents[2]
RUN = Path(__file__).parent / "data" / "ntrt-recordings" / "TetraSpine" / "random-00"


def _trial(options: dict) -> tuple[float, np.ndarray]:
    morph = load_morphology("tetraspine-ntrt2026")
    cfg = TrialConfig(duration_s=0.3, dt_s=0.001, motor_model="ntrt2026", controller="ntrt", engine="bullet",
                      engine_options={"friction_anchor": False, **options}, record_every_s=0.01)
    out = simulate(morph, unit_params(morph, read_parameter_set(RUN)), cfg, 0)
    return out.result.ntrt_distance_cm, out.trajectory.arrays()["poses"][..., :3]


def test_the_mlcp_dantzig_solver_is_the_one_bullet_runs(capfd):
    default_cm, _ = _trial({})
    assert "MLCP + Dantzig" not in "".join(capfd.readouterr())
    mlcp_cm, pos_cm = _trial({"constraint_solver": "mlcp_dantzig"})
    said = capfd.readouterr()
    assert "MLCP + Dantzig" in said.err and "MLCP + Dantzig" not in said.out  # pybullet's own message, on stderr
    assert mlcp_cm != default_cm
    # the robot lands and stays up: no segment's centre falls through the ground (top at 0.5 cm) under it
    assert np.isfinite(pos_cm).all() and pos_cm[..., 1].min() > 0.5


def test_an_unknown_solver_is_refused():
    with pytest.raises(ConfigError, match="constraint_solver"):
        TrialConfig(engine="bullet", engine_options={"constraint_solver": "lemke"})


def test_trial_json_stays_clean_json_under_the_mlcp_solver():
    """pybullet prints its switch of solver from C on file descriptor 1; `spinefarm trial --json` keeps it off
    stdout (on stderr), so that its stdout is one JSON document."""
    argv = ["trial", "tetraspine-ntrt", "--engine", "bullet", "--engine-option", "constraint_solver=mlcp_dantzig",
            "--duration", "0.2", "--json"]
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}  # C's stdout buffered, as usually
    proc = subprocess.run([sys.executable, "-m", "spinefarm", *argv], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "MLCP + Dantzig" in proc.stderr
    out = json.loads(proc.stdout)
    assert out["status"] == "complete" and out["sim_time_s"] == 0.2


def test_c_text_still_buffered_when_the_redirect_ends_goes_to_stderr():
    """C's stdout is fully buffered into a pipe: text printed without a flush inside the redirect must be flushed
    while file descriptor 1 is still stderr, or it would reach stdout at exit."""
    code = ("import ctypes; from spinefarm.worker.engines.bullet import _stdout_to_stderr\n"
            "with _stdout_to_stderr():\n    ctypes.CDLL(None).printf(b'unflushed C text')\n"
            "print('{}')\n")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}  # it would unbuffer C's stdout too
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert "unflushed C text" in proc.stderr and json.loads(proc.stdout) == {}


def test_two_threads_setting_worlds_up_leave_stdout_on_stdout():
    """Thread B enters the redirect while A is inside it and leaves after A: were they not taken in turn, B would
    restore the descriptor it saved (stderr) last, and stdout would stay on stderr."""
    code = """
import os, threading
from spinefarm.worker.engines.bullet import _stdout_to_stderr
a_in, b_in, a_out = threading.Event(), threading.Event(), threading.Event()
def a():
    with _stdout_to_stderr():
        a_in.set()
        b_in.wait(0.5)   # B, taken in turn, cannot come in before A leaves
    a_out.set()
def b():
    a_in.wait()
    with _stdout_to_stderr():
        b_in.set()
        a_out.wait()
threads = [threading.Thread(target=f) for f in (a, b)]
for t in threads:
    t.start()
for t in threads:
    t.join()
os.write(1, b"{}")
"""
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout) == {}
