"""What a user installing the wheel gets: docs from `spinefarm docs`, NTRT's parameter sets by name, the
dashboard's assets, and a first trial that says it is compiling. Run from an unpacked wheel in a folder
away from the source tree (python -P), with a cold compilation cache."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from tests.coordinator_tests.procs import ROOT

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def wheel_tree(tmp_path_factory):
    d = tmp_path_factory.mktemp("wheel")
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w",
                        str(d), str(ROOT)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    wheel = next(d.glob("spinefarm-*.whl"))
    tree = d / "site"
    with zipfile.ZipFile(wheel) as z:
        names = z.namelist()
        z.extractall(tree)
    return tree, names


def spinefarm(tree: Path, *args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    return subprocess.run([sys.executable, "-P", "-m", "cli.main", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=600)


def test_the_wheel_carries_docs_data_and_browser_assets(wheel_tree):
    _, names = wheel_tree
    for needed in ("spinefarm/__init__.py", "spinefarm/docs/replay.md", "spinefarm/docs/README.md",
                   "api/static/index.html", "api/static/vendor/plotly-basic.min.js",
                   "api/static/vendor/LICENSE-plotly.js.txt", "api/static/vendor/redoc.standalone.js",
                   "api/static/vendor/swagger/swagger-ui-bundle.js", "worker/replay_data/LICENSE",
                   "worker/replay_data/NOTICE",
                   "worker/replay_data/OctahedralComplex/paper-2014-06-07/logs/bestParameters-default_node-0.nnw"):
        assert needed in names, needed


def test_docs_are_reachable_from_help(wheel_tree, tmp_path):
    tree, _ = wheel_tree
    assert "docs" in spinefarm(tree, "--help", cwd=tmp_path).stdout
    listing = spinefarm(tree, "docs", cwd=tmp_path)
    assert listing.returncode == 0 and "replay" in listing.stdout and "overview" in listing.stdout
    page = spinefarm(tree, "docs", "replay", cwd=tmp_path)
    assert page.returncode == 0 and "spinefarm replay octahedral-complex" in page.stdout
    bad = spinefarm(tree, "docs", "nonsense", cwd=tmp_path)
    assert bad.returncode == 2 and "no such documentation topic" in bad.stderr


def test_replay_by_name_and_a_first_trial_says_it_compiles(wheel_tree, tmp_path):
    tree, _ = wheel_tree
    first = spinefarm(tree, "trial", "tetraspine-ntrt", "--duration", "0.1", cwd=tmp_path)
    assert first.returncode == 0, first.stderr
    assert "compiling" in first.stderr  # a fresh install: numba's cache is cold
    r = spinefarm(tree, "replay", "octahedral-complex", "--duration", "0.5", "--json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["morphology"] == "octahedral-complex" and out["n_edge_files"] == 26
    assert str(tree) in out["path"]
    again = spinefarm(tree, "trial", "tetraspine-ntrt", "--duration", "0.1", cwd=tmp_path)
    assert again.returncode == 0 and "compiling" not in again.stderr
