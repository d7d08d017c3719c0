"""What a user installing the wheel gets: docs from `spinefarm docs`, NTRT's parameter sets by name, the
dashboard's assets, and a first trial that says it is compiling. Run from an unpacked wheel in a folder
away from the source tree (python -P), with a cold compilation cache."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import urllib.request
import zipfile
from pathlib import Path

import pytest

from tests.api_tests.test_dashboard_browser import free_port
from tests.coordinator_tests.helpers import wait_for
from tests.coordinator_tests.procs import ROOT

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def wheel_tree(tmp_path_factory):
    d = tmp_path_factory.mktemp("wheel")
    # built from a copy of the tracked files: setuptools builds in the source tree's build/, which two test
    # processes building at once would share
    src = d / "src"
    listed = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True)
    if listed.returncode != 0:  # not a git checkout: the tree without what builds and runs leave
        shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(".venv", "build", "runs", "*.egg-info", ".git"))
    for name in filter(None, listed.stdout.decode().split("\0") if listed.returncode == 0 else []):
        if (ROOT / name).is_file():
            (src / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, src / name)
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w",
                        str(d), str(src)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    wheel = next(d.glob("spinefarm-*.whl"))
    tree = d / "site"
    with zipfile.ZipFile(wheel) as z:
        names = z.namelist()
        z.extractall(tree)
    return tree, names


def spinefarm(tree: Path, *args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    return subprocess.run([sys.executable, "-P", "-m", "spinefarm", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=600)


def test_the_wheel_carries_docs_data_and_browser_assets(wheel_tree):
    _, names = wheel_tree
    for needed in ("spinefarm/__init__.py", "spinefarm/protocol/columns.toml", "spinefarm/docs/replay.md",
                   "spinefarm/docs/README.md",
                   "spinefarm/api/static/index.html", "spinefarm/api/static/vendor/plotly-basic.min.js",
                   "spinefarm/api/static/vendor/LICENSE-plotly.js.txt",
                   "spinefarm/api/static/vendor/redoc.standalone.js",
                   "spinefarm/api/static/vendor/swagger/swagger-ui-bundle.js",
                   "spinefarm/api/static/gait3d.js", "spinefarm/api/static/run_views.js",
                   "spinefarm/api/static/favicon.svg", "spinefarm/api/static/vendor/three/three.module.min.js",
                   "spinefarm/api/static/vendor/three/three.core.min.js",
                   "spinefarm/api/static/vendor/three/OrbitControls.js",
                   "spinefarm/api/static/vendor/three/LICENSE-three.txt", "spinefarm/worker/replay_data/LICENSE",
                   "spinefarm/worker/replay_data/NOTICE",
                   "spinefarm/worker/replay_data/OctahedralComplex/paper-2014-06-07/logs/bestParameters-default_node-0.nnw"):
        assert needed in names, needed
    # every script and style the dashboard page loads
    page = (ROOT / "spinefarm" / "api" / "static" / "index.html").read_text()
    for asset in re.findall(r'"/static/([^"]+)"', page):
        assert f"spinefarm/api/static/{asset}" in names, asset


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


def test_installed_code_lives_under_the_spinefarm_namespace_only(wheel_tree):
    _, names = wheel_tree
    tops = {n.split("/", 1)[0] for n in names}
    assert {t for t in tops if not t.endswith(".dist-info")} == {"spinefarm"}, tops


def test_a_folder_with_its_own_cli_worker_api_and_storage_packages_shadows_nothing(wheel_tree, tmp_path):
    """The user's folder comes first on sys.path (`python -m`, `python -c`): generic names there must not matter."""
    tree, _ = wheel_tree
    for pkg in ("cli", "worker", "api", "storage", "protocol", "robot", "coordinator"):
        (tmp_path / pkg).mkdir()
        (tmp_path / pkg / "__init__.py").write_text("raise ImportError('the user\\'s own package was imported')\n")
    env = {**os.environ, "PYTHONPATH": str(tree)}

    def run(*cmd: str) -> subprocess.CompletedProcess:
        r = subprocess.run([sys.executable, *cmd], cwd=tmp_path, env=env, capture_output=True, text=True,
                           timeout=600)
        assert r.returncode == 0, r.stderr[-2000:]
        return r

    run("-m", "spinefarm", "search", "tetraspine-ntrt", "--trials", "1", "--workers", "1", "--duration", "0.3",
        "--out", "run.h5", "--api-port", "-1", "--quiet", "--engine", "bullet")
    rows = run("-c", "import spinefarm; print(len(spinefarm.load_run('run.h5')))")
    assert int(rows.stdout) >= 1
    port = free_port()
    api = subprocess.Popen([sys.executable, "-m", "spinefarm", "api", "run.h5", "--port", str(port)], cwd=tmp_path,
                           env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        url = f"http://127.0.0.1:{port}"
        wait_for(lambda: _answers(url + "/health", api), timeout_s=60, poll_s=0.2, what="the API to answer")
        with urllib.request.urlopen(url + "/runs", timeout=10) as resp:
            run_id = json.load(resp)[0]["run_id"]
        with urllib.request.urlopen(f"{url}/runs/{run_id}/trials/0/picture.png", timeout=300) as resp:
            assert resp.headers["content-type"] == "image/png" and resp.read(8) == b"\x89PNG\r\n\x1a\n"
    finally:
        api.terminate()
        api.wait(30)


def _answers(url: str, proc: subprocess.Popen) -> bool:
    assert proc.poll() is None, proc.stderr.read()
    try:
        with urllib.request.urlopen(url, timeout=1):
            return True
    except OSError:
        return False


@pytest.fixture(scope="module")
def fresh_venv(wheel_tree, tmp_path_factory):
    """The wheel installed by pip into a new venv (the README's wheel route); its dependencies are the ones of
    this interpreter, seen through a .pth file (no index needed: the test installs nothing else)."""
    import numpy

    tree, _ = wheel_tree
    wheel = next(tree.parent.glob("spinefarm-*.whl"))
    venv = tmp_path_factory.mktemp("fresh") / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    r = subprocess.run([sys.executable, "-m", "pip", "--python", str(venv / "bin" / "python"), "install", "-q",
                        "--no-deps", "--no-index", "--disable-pip-version-check", str(wheel)],
                       capture_output=True, text=True, timeout=300, cwd=venv.parent,
                       env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"})  # this checkout is no install
    assert r.returncode == 0, r.stderr
    site = next((venv / "lib").glob("python3*/site-packages"))
    (site / "zz-dependencies.pth").write_text(str(Path(numpy.__file__).resolve().parents[1]) + "\n")
    return venv


def installed(venv: Path, *args: str, cwd: Path, program: str = "spinefarm") -> subprocess.CompletedProcess:
    """A program of the venv (its console script by default), without this checkout on the path."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    return subprocess.run([str(venv / "bin" / program), *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=600)


def test_the_wheel_installed_in_a_fresh_venv_writes_the_readmes_examples(fresh_venv, tmp_path):
    where = installed(fresh_venv, "-c", "import spinefarm; print(spinefarm.__file__)", cwd=tmp_path, program="python")
    assert where.stdout.startswith(str(fresh_venv)), where.stdout + where.stderr  # the installed copy runs
    help_text = installed(fresh_venv, "--help", cwd=tmp_path)
    assert help_text.returncode == 0 and "examples" in help_text.stdout and "docs" in help_text.stdout
    r = installed(fresh_venv, "examples", "examples", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    shipped = sorted(p.relative_to(ROOT / "examples") for p in (ROOT / "examples").rglob("*.json"))
    written = sorted(p.relative_to(tmp_path / "examples") for p in (tmp_path / "examples").rglob("*.json"))
    assert written == shipped and len(shipped) >= 10
    for rel in shipped:
        assert (tmp_path / "examples" / rel).read_bytes() == (ROOT / "examples" / rel).read_bytes(), rel
    assert "name: my-spine" in (tmp_path / "examples" / "my_spine.yaml").read_text()
    # as the README uses them: a gait file by its path, the spec to start a robot from
    trial = installed(fresh_venv, "trial", "tetraspine", "--params", "examples/gaits/tetraspine.json",
                      "--duration", "0.2", cwd=tmp_path)
    assert trial.returncode == 0, trial.stderr[-2000:]
    assert installed(fresh_venv, "check", "examples/my_spine.yaml", cwd=tmp_path).returncode == 0
    again = installed(fresh_venv, "examples", "examples", cwd=tmp_path)  # nothing written is replaced
    assert again.returncode == 2 and "already exist in examples" in again.stderr and "--overwrite" in again.stderr


def test_the_wheel_says_which_pythons_it_installs_on_and_leaves_pybullet_out_where_it_has_no_wheel(wheel_tree):
    from packaging.requirements import Requirement
    from packaging.specifiers import SpecifierSet

    tree, _ = wheel_tree
    meta = next(tree.glob("spinefarm-*.dist-info")) / "METADATA"
    lines = meta.read_text().splitlines()
    python = SpecifierSet(next(ln.split(":", 1)[1].strip() for ln in lines if ln.startswith("Requires-Python:")))
    assert [v in python for v in ("3.10", "3.11.7", "3.12.1", "3.13.0", "3.14.0")] == [False, True, True, True, False]
    bullet = next(Requirement(ln.split(":", 1)[1]) for ln in lines if ln.startswith("Requires-Dist: pybullet"))
    # pybullet 3.2.7 publishes wheels for CPython up to 3.11: elsewhere pip must not try to compile it
    assert [bullet.marker.evaluate({"python_version": v, "extra": "worker"}) for v in ("3.11", "3.12", "3.13")] == [
        True, False, False]

