"""A run file on a file system without locks (NFS without its lock service, Lustre without -o flock): the
search says so and how to go on, and with HDF5_USE_FILE_LOCKING=FALSE it runs, resumes and is read.

The file system is a folder whose flock() a preloaded wrapper refuses with ENOLCK, as such
a mount does (data/nolock.c, compiled by gcc, which the machine has); every other file keeps its locks."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from spinefarm.storage.hdf5_reader import read_run
from tests.coordinator_tests.procs import ROOT

SHIM_SOURCE = Path(__file__).parent / "data" / "nolock.c"


@pytest.fixture(scope="module")
def shim(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("shim") / "nolock.so"
    cc = shutil.which("gcc") or shutil.which("cc")
    assert cc, "a C compiler (gcc) builds the ENOLCK file system's stand-in"
    subprocess.run([cc, "-shared", "-fPIC", "-O2", "-o", str(out), str(SHIM_SOURCE), "-ldl"], check=True)
    return out


def run(shim: Path, nolock_dir: Path, *args: str, waive: bool = False) -> subprocess.CompletedProcess:
    env = {**os.environ, "LD_PRELOAD": str(shim), "NOLOCK_DIR": str(nolock_dir) + "/"}
    env.pop("HDF5_USE_FILE_LOCKING", None)
    if waive:
        env["HDF5_USE_FILE_LOCKING"] = "FALSE"
    return subprocess.run([sys.executable, "-m", "spinefarm", *args], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=180)


def search(*extra: str) -> list[str]:
    return ["search", "sphere:3", "--workers", "1", "--api-port", "-1", "--quiet", *extra]


def test_a_file_system_without_locks_is_named_and_the_waiver_runs_the_search(shim, tmp_path):
    mount = tmp_path / "nfs"
    mount.mkdir()
    out = mount / "run.h5"
    refused = run(shim, mount, *search("--trials", "3", "--out", str(out)))
    assert refused.returncode == 2, refused.stderr
    assert "cannot lock run file" in refused.stderr and "No locks available" in refused.stderr
    assert "HDF5_USE_FILE_LOCKING=FALSE" in refused.stderr and "Traceback" not in refused.stderr
    assert not out.exists()

    done = run(shim, mount, *search("--trials", "3", "--out", str(out)), waive=True)
    assert done.returncode == 0, done.stderr
    assert "written without a lock" in done.stderr
    resumed = run(shim, mount, "search", "--resume", str(out), "--trials", "5", "--workers", "1", "--api-port", "-1",
                  "--quiet", waive=True)
    assert resumed.returncode == 0, resumed.stderr
    _, cols = read_run(out)  # this process keeps its locks: the file is an ordinary run file
    assert (cols["status"] == b"complete").sum() == 5

    unread = run(shim, mount, "export", str(out), "--csv", str(tmp_path / "t.csv"))
    assert unread.returncode == 2 and "HDF5_USE_FILE_LOCKING=FALSE" in unread.stderr, unread.stderr
    read = run(shim, mount, "export", str(out), "--csv", str(tmp_path / "t.csv"), waive=True)
    assert read.returncode == 0, read.stderr
    assert len((tmp_path / "t.csv").read_text().splitlines()) == 6


@pytest.mark.parametrize(("value", "waived"), [("FALSE", True), ("0", True), ("false", False), ("TRUE", False),
                                               ("BEST_EFFORT", False), (None, False)])
def test_the_waiver_reads_hdf5s_switch_as_hdf5_does(monkeypatch, value, waived):
    from spinefarm.storage.runlock import locks_waived

    if value is None:
        monkeypatch.delenv("HDF5_USE_FILE_LOCKING", raising=False)
    else:
        monkeypatch.setenv("HDF5_USE_FILE_LOCKING", value)
    assert locks_waived() is waived
