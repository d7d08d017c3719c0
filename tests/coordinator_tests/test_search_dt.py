"""--dt on search and coordinator: the hardware Tetraspine (stiff strings) is searched at a stable step by default."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np

from spinefarm.storage.hdf5_reader import read_run
from tests.coordinator_tests.procs import ROOT


def search(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "spinefarm", "search", *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=300, env=env)


def test_tetraspine_hardware_is_searched_with_defaults_at_a_stable_step_and_refused_at_an_unstable_one(tmp_path):
    common = ("tetraspine-hardware", "--trials", "2", "--workers", "1", "--duration", "0.3", "--api-port", "-1",
              "--no-verify", "--quiet")
    small = ("--calibrate-gaits", "4", "--calibrate-search-trials", "2", "--calibrate-bests", "1",
             "--calibrate-duration", "0.3", "--calibrate-settle", "0.1")
    refused = search(*common, "--dt", "0.001", "--out", str(tmp_path / "a.h5"))
    assert refused.returncode == 2 and "dt_s is unstable" in refused.stderr and "--dt auto" in refused.stderr
    env = {**os.environ, "SPINEFARM_CACHE_DIR": str(tmp_path / "cache")}
    ok = search(*common, *small, "--out", str(tmp_path / "b.h5"), env=env)
    assert ok.returncode == 0, ok.stderr[-2000:]
    # the stable-step estimate of its strings is 0.509 ms (docs/stability.md); half of it is taken
    assert "step: 0.254 ms for tetraspine-hardware (the default step, mujoco's 1 ms, bullet's 1 ms, is above its " \
           "stable limit of 0.509 ms; --dt sets another)" in ok.stderr
    meta, cols = read_run(tmp_path / "b.h5")
    assert meta.trial_config["auto_dt"] is True
    # engine auto (search's default) calibrated at that step too, and chose
    assert "the calibration could not run" not in ok.stderr and meta.settings.engine_choice is not None
    assert list(cols["status"]) == [b"complete", b"complete"]
    assert "re-simulates" not in ok.stderr  # --no-verify: no judge runs, so none is announced
    assert np.all(cols["dt_s"] < 5.1e-4)  # the automatic step, below the stable limit, stored per trial
    bad = search(*common, "--dt", "fast", "--out", str(tmp_path / "c.h5"))
    assert bad.returncode == 2 and "--dt is not a number" in bad.stderr


def test_a_mujoco_search_whose_trials_are_all_re_run_with_contacts_finishes(tmp_path):
    """The ribbed spine's ribs start 2 mm apart: MuJoCo's contact guard re-runs every trial with the segment
    contacts and notes it in the result. That note once outgrew the protocol's limit on a note, the coordinator
    refused every batch, and the search waited for ever at 0 of 2."""
    out = tmp_path / "ribbed.h5"
    r = search("ribbed", "--engine", "mujoco", "--trials", "2", "--duration", "0.2", "--workers", "1", "--out",
               str(out), "--no-verify", "--api-port", "-1")
    assert r.returncode == 0, r.stderr[-2000:]
    assert "malformed" not in r.stderr, r.stderr[-2000:]
    _, cols = read_run(out)
    assert cols["status"].tolist() == [b"complete", b"complete"]
