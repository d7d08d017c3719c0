"""A disk that fills up once every result is stored: the search still ends with its report and rc 0 (with a
warning), leaves no temporary status file, and no status file that says the run is still going."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from spinefarm.storage.hdf5_reader import read_run
from tests.coordinator_tests.procs import ROOT

# The search in a child process; the disk is filled (a real tmpfs, written until ENOSPC) when the session starts
# to close: every trial is stored by then and its status file written at least once (so a stale one would say
# "running").
_DRIVER = """
import os, sys, time
from spinefarm.cli import search_loop
from spinefarm.cli.main import main
from spinefarm.storage.status import status_path

run = sys.argv[1]
close = search_loop.SearchSession.close

def fill_then_close(self):
    end = time.monotonic() + 20
    while not status_path(run).exists() and time.monotonic() < end:
        time.sleep(0.05)
    fd = os.open(os.path.join(os.path.dirname(run), "filler"), os.O_WRONLY | os.O_CREAT)
    try:
        while True:
            os.write(fd, bytes(4096))
    except OSError:
        pass
    finally:
        os.close(fd)
    close(self)

search_loop.SearchSession.close = fill_then_close
sys.exit(main(["search", "sphere:3", "--trials", "40", "--workers", "1", "--out", run, "--api-port", "-1",
               "--quiet"]))
"""


@pytest.fixture
def fs_16mb(tmp_path):
    """A tmpfs with room for the run file's 8 MB reserve (storage.hdf5.RESERVE_B) and its status file."""
    mnt = tmp_path / "fs"
    mnt.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=16m", "tmpfs", str(mnt)], capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs to fill up (needs root): {r.stderr.strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def test_a_disk_full_at_the_end_still_reports_with_rc_0_and_a_true_status(fs_16mb: Path):
    run = fs_16mb / "run.h5"
    r = subprocess.run([sys.executable, "-c", _DRIVER, str(run)], cwd=ROOT, capture_output=True, text=True,
                       timeout=180)
    assert (fs_16mb / "filler").stat().st_size > 0  # the disk did fill up
    assert r.returncode == 0, r.stderr[-2000:]
    assert "search done: 40 parameter sets, 40 evaluations of sphere:3" in r.stdout, r.stdout
    assert "best trial " in r.stdout, r.stdout
    warnings = [ln for ln in r.stderr.splitlines() if ln.startswith("warning: ")]
    assert len(warnings) == 1 and "No space left on device" in warnings[0], r.stderr
    assert "Traceback" not in r.stderr and "error:" not in r.stderr, r.stderr
    assert sorted(p.name for p in fs_16mb.iterdir() if p.name.startswith("run.h5.")) in (
        ["run.h5.lock"], ["run.h5.lock", "run.h5.status.json"])
    status = run.with_name("run.h5.status.json")
    if status.exists():  # none at all is true as well: readers then take the state from the run file
        assert json.loads(status.read_text())["state"] == "done"
    _, cols = read_run(run)
    assert np.count_nonzero(cols["status"] == b"complete") == 40
