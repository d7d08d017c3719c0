"""The run lock on a file system without locks, in one process each (no search): flock refused with ENOLCK
(data/nolock.c, as NFS without its lock service refuses it) is named with the way out; with
HDF5_USE_FILE_LOCKING=FALSE the lock is taken without its name lock, says so, and still records its pid
(storage/runlock.py, docs/reliability.md)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SNIPPET = """
import json, logging, os, sys
logging.basicConfig(stream=sys.stderr, level=logging.WARNING, format="%(message)s")
from spinefarm.protocol.errors import StorageError
from spinefarm.storage.runlock import RunLock
try:
    lock = RunLock(sys.argv[1]).acquire()
except StorageError as exc:
    print(json.dumps({"error": str(exc)}))
else:
    print(json.dumps({"pid": os.getpid(), "sidecar": open(sys.argv[1] + ".lock").read()}))
"""


@pytest.fixture(scope="module")
def shim(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("shim") / "nolock.so"
    cc = shutil.which("gcc") or shutil.which("cc")
    assert cc, "a C compiler (gcc) builds the ENOLCK file system's stand-in"
    subprocess.run([cc, "-shared", "-fPIC", "-O2", "-o", str(out), str(Path(__file__).parent / "data" / "nolock.c"),
                    "-ldl"], check=True)
    return out


def _acquire(shim: Path, mount: Path, waive: bool) -> tuple[dict, str]:
    env = {k: v for k, v in os.environ.items() if k != "HDF5_USE_FILE_LOCKING"}
    env.update(LD_PRELOAD=str(shim), NOLOCK_DIR=str(mount) + "/")
    if waive:
        env["HDF5_USE_FILE_LOCKING"] = "FALSE"
    r = subprocess.run([sys.executable, "-c", SNIPPET, str(mount / "run.h5")], cwd=ROOT, env=env, capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout), r.stderr


def test_no_locks_is_named_with_the_way_out_and_the_waiver_takes_the_lock(shim, tmp_path) -> None:
    mount = tmp_path / "nfs"
    mount.mkdir()
    refused, _ = _acquire(shim, mount, waive=False)
    assert "its file system offers no locks" in refused["error"], refused
    assert "HDF5_USE_FILE_LOCKING=FALSE" in refused["error"], refused
    taken, said = _acquire(shim, mount, waive=True)
    assert taken["sidecar"] == f"{taken['pid']}\n", taken
    assert f"run file {mount / 'run.h5'} is written without a lock" in said, said
