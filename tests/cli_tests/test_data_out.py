"""Data out in one call: spinefarm.load_run gives a DataFrame; `export --parquet` writes the same table."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

import spinefarm
from spinefarm.storage.hdf5_reader import read_run
from tests.coordinator_tests.procs import ROOT


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "spinefarm", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=120)


@pytest.fixture(scope="module")
def sphere_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("data") / "sphere.h5"
    r = run("search", "sphere:4", "--trials", "120", "--workers", "1", "--out", str(out), "--api-port", "-1",
            "--quiet", "--run-id", "data-out")
    assert r.returncode == 0, r.stderr
    return out


def test_load_run_is_one_row_per_trial_with_named_parameters_and_units(sphere_run):
    meta, cols = read_run(sphere_run)
    df = spinefarm.load_run(sphere_run)
    assert len(df) == len(cols["trial_id"]) == 120
    assert df.index.name == "trial_id" and df.index.tolist() == list(range(120))
    assert list(meta.param_names) == ["x0", "x1", "x2", "x3"]
    np.testing.assert_allclose(df[list(meta.param_names)].to_numpy(), cols["params"])
    np.testing.assert_allclose(df["distance_m"].to_numpy(), cols["distance_m"])
    assert set(df["status"]) == {"complete"}
    assert df.attrs["units"]["speed_cm_s"] == "cm/s" and df.attrs["units"]["distance_m"] == "m"
    assert df.attrs["units"]["x0"] == meta.param_units[0]
    assert df.attrs["run"]["run_id"] == "data-out" and df.attrs["run"]["objective"] == "distance"
    assert isinstance(spinefarm.__version__, str) and spinefarm.__version__


def test_export_parquet(sphere_run, tmp_path):
    out = tmp_path / "trials.parquet"
    r = run("export", str(sphere_run), "--parquet", str(out))
    assert r.returncode == 0, r.stderr
    assert f"wrote 120 trials to {out}" in r.stderr
    back = pd.read_parquet(out)
    df = spinefarm.load_run(sphere_run)
    pd.testing.assert_frame_equal(back, df, check_like=False)
    assert back.attrs["units"]["speed_cm_s"] == "cm/s"
    bad = run("export", str(sphere_run), "--parquet", str(tmp_path / "trials.csv"))
    assert bad.returncode == 2 and "--parquet has the wrong extension" in bad.stderr
    assert "Traceback" not in bad.stderr
