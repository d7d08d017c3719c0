"""A co-designed search stopped and resumed continues exactly: the same bodies, gaits and distances, bit for bit,
as the same search run through in one go."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from spinefarm.storage.hdf5_reader import read_run
from tests.cli_tests.test_codesign import ROOT, SPEC

# the paper's sampler: 3 Monte Carlo trials, then hill climbing from the best stored so far, so the trials
# after the resume depend on the scores read back from the file
FLAGS = ("--workers", "1", "--batch", "1", "--duration", "0.2", "--engine", "bullet", "--sampler", "paper",
         "--startup-trials", "3", "--seed", "5", "--no-verify", "--api-port", "-1", "--quiet")
COLUMNS = ("params_unit", "params", "seed", "status", "reason", "body_hash", "distance_m", "cot", "phase", "parent")


def search(*args: str) -> None:
    r = subprocess.run([sys.executable, "-m", "spinefarm", "search", *args], cwd=ROOT, capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stderr


@pytest.mark.slow  # three searches: 40 s measured under a load of 10-12
def test_a_resumed_codesigned_search_continues_exactly(tmp_path: Path):
    spec = tmp_path / "co.yaml"
    spec.write_text(SPEC)
    whole, halves = tmp_path / "whole.h5", tmp_path / "halves.h5"
    search(str(spec), "--trials", "8", *FLAGS, "--run-id", "co", "--out", str(whole))
    search(str(spec), "--trials", "5", *FLAGS, "--run-id", "co", "--out", str(halves))
    spec.unlink()  # the resume has the run file only
    search("--resume", str(halves), "--trials", "8", *FLAGS[:4], "--no-verify", "--api-port", "-1", "--quiet")
    _, a = read_run(whole)
    _, b = read_run(halves)
    assert len(a["trial_id"]) == len(b["trial_id"]) == 8
    for name in COLUMNS:
        x, y = np.asarray(a[name]), np.asarray(b[name])
        assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), name
    # the search did climb on co-designed bodies after the resume, over more than one body
    assert len(set(np.asarray(b["body_hash"]).tolist())) >= 4
    assert (np.asarray(b["parent"])[3:] >= 0).all()
