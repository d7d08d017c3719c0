"""The environment record: what it holds, what a run file keeps of it, and saying plainly what differs."""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np

from spinefarm.protocol.environment import describe_differences, differences, environment_record

ROOT = Path(__file__).resolve().parents[2]


def test_the_record_names_python_packages_cpu_blas_and_commit():
    rec = environment_record()
    assert rec["python"] == platform.python_version()
    assert rec["packages"]["numpy"] == np.__version__
    assert rec["packages"]["spinefarm"] == rec["spinefarm_version"]
    assert rec["cpu_model"] and "sse2" in rec["cpu_flags"].split()
    assert rec["blas"]["kernel"] and rec["blas"]["library"]
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True).stdout
    assert rec["spinefarm_commit"].split("+")[0] == head.strip()
    json.dumps(rec)


def test_differences_name_what_changed_and_nothing_else():
    rec = environment_record()
    assert differences(rec, rec) == [] and describe_differences(rec, rec) == ""
    old = {**rec, "python": "3.11.0", "packages": {**rec["packages"], "numpy": "1.26.0"}, "cpu_model": "Other CPU"}
    lines = differences(old, rec)
    assert lines[0] == "Python " + rec["python"] + " here, 3.11.0 in the run"
    assert f"numpy {np.__version__} here, 1.26.0 in the run" in lines
    assert any(line.startswith("CPU ") for line in lines) and len(lines) == 3
    assert differences(None, rec) == ["the run file records no environment (written before spinefarm recorded one)"]


def _cli(*args: str, timeout: float = 300, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    base = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    return subprocess.run([sys.executable, "-m", "spinefarm", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=timeout, env={**base, **(env or {})})


def _forge_numpy_version(path: Path, version: str) -> None:
    with h5py.File(path, "r+") as f:
        env = json.loads(f.attrs["environment"])
        env["packages"]["numpy"] = version
        f.attrs["environment"] = json.dumps(env, sort_keys=True)


def test_a_run_file_records_it_and_trial_run_and_resume_say_what_differs(tmp_path):
    out = tmp_path / "run.h5"
    r = _cli("search", "tetraspine", "--trials", "2", "--workers", "1", "--duration", "0.2", "--out", str(out),
             "--api-port", "-1", "--no-verify", "--engine", "bullet")
    assert r.returncode == 0, r.stderr
    with h5py.File(out, "r") as f:
        stored = json.loads(f.attrs["environment"])
    assert stored["packages"]["numpy"] == np.__version__ and stored["python"] == platform.python_version()
    assert stored["blas"]["threads"] == 1  # the command's processes run BLAS on one thread each
    same = _cli("trial", "--run", str(out), "--json")
    assert same.returncode == 0 and "environment differs" not in same.stderr, same.stderr
    assert json.loads(same.stdout.splitlines()[-1])["environment"]["packages"]["numpy"] == np.__version__
    told = _cli("trial", "--run", str(out), "--json", env={"OPENBLAS_NUM_THREADS": "2"})  # a user's choice stays
    assert json.loads(told.stdout.splitlines()[-1])["environment"]["blas"]["threads"] == 2, told.stderr
    _forge_numpy_version(out, "1.26.0")
    rerun = _cli("trial", "--run", str(out), "--json")
    assert rerun.returncode == 0, rerun.stderr
    assert f"the environment differs from the run's: numpy {np.__version__} here, 1.26.0 in the run" in rerun.stderr
    resumed = _cli("search", "--resume", str(out), "--workers", "1", "--api-port", "-1")
    assert resumed.returncode == 0, resumed.stderr
    assert f"numpy {np.__version__} here, 1.26.0 in the run" in resumed.stderr


def test_the_record_keeps_the_variables_that_steer_blas_and_numba(monkeypatch):
    """docs/reproducibility.md: OPENBLAS_CORETYPE, OPENBLAS_L2_SIZE, NUMBA_CPU_NAME, NUMBA_CPU_FEATURES and
    NUMBA_OPT are recorded with their values; other variables are not; a changed one is told."""
    steering = {"OPENBLAS_CORETYPE": "Haswell", "OPENBLAS_L2_SIZE": "262144", "NUMBA_CPU_NAME": "generic",
                "NUMBA_CPU_FEATURES": "+sse2", "NUMBA_OPT": "2"}
    for name in steering:
        monkeypatch.delenv(name, raising=False)
    assert environment_record()["env"] == {}
    monkeypatch.setenv("SPINEFARM_UNRELATED", "1")
    for name, value in steering.items():
        monkeypatch.setenv(name, value)
    rec = environment_record()
    assert rec["env"] == steering
    monkeypatch.setenv("NUMBA_OPT", "0")
    told = differences(rec)
    assert told == [f"environment variables {dict(steering, NUMBA_OPT='0')} here, {steering} in the run"]


def test_without_a_checkout_of_its_own_the_commit_is_spinefarm_commit(tmp_path, monkeypatch):
    """A package copied into some other git repository (an image's source tree, a vendored copy) is not that
    repository's commit: SPINEFARM_COMMIT says what it is."""
    import importlib.util
    import shutil

    outer = tmp_path / "someone-elses-repo"
    copy = outer / "vendored" / "spinefarm" / "protocol" / "environment.py"
    copy.parent.mkdir(parents=True)
    shutil.copy(ROOT / "spinefarm" / "protocol" / "environment.py", copy)
    for args in (["init", "-q"], ["-c", "user.name=t", "-c", "user.email=t@t", "commit", "-q", "--allow-empty",
                                  "-m", "x"]):
        subprocess.run(["git", "-C", str(outer), *args], check=True, capture_output=True)
    spec = importlib.util.spec_from_file_location("vendored_environment", copy)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    monkeypatch.setenv("SPINEFARM_COMMIT", "0123abc")
    assert module._commit() == "0123abc"
    monkeypatch.delenv("SPINEFARM_COMMIT")
    assert module._commit() is None
