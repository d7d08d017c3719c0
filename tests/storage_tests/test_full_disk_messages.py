"""A full disk: one clear message and no traceback from the search; a failed resume leaves no .resume-tmp."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import pytest

from spinefarm.coordinator.setup import resume_run
from spinefarm.protocol.errors import StorageError
from tests.coordinator_tests.procs import ROOT
from tests.coordinator_tests.test_run_file_faults import finished_run, small_fs  # noqa: F401 (a fixture)


def test_search_on_a_full_disk_prints_no_traceback(small_fs):  # noqa: F811
    r = subprocess.run([sys.executable, "-m", "spinefarm", "search", "sphere:8", "--trials", "1000000", "--workers",
                        "1", "--batch", "64", "--out", str(small_fs / "run.h5"), "--api-port", "-1", "--quiet"],
                       cwd=ROOT, capture_output=True, text=True, timeout=180)
    assert r.returncode == 1 and "No space left on device" in r.stderr
    assert "Traceback" not in r.stderr and "Exception ignored" not in r.stderr, r.stderr[-3000:]


def test_a_resume_that_fails_on_a_full_disk_leaves_no_temporary_file(small_fs, tmp_path):  # noqa: F811
    src = tmp_path / "run.h5"
    finished_run(src, n=40)
    path = small_fs / "run.h5"
    shutil.copy(src, path)
    fd = os.open(small_fs / "filler", os.O_WRONLY | os.O_CREAT)  # no room left for a copy of the run
    try:
        while True:
            os.write(fd, b"\0" * 4096)
    except OSError:
        pass
    finally:
        os.close(fd)
    with pytest.raises(StorageError, match="cannot write the resumed copy"):
        resume_run(path)
    assert not (small_fs / "run.h5.resume-tmp").exists()


def fill(folder) -> None:
    fd = os.open(folder / "filler", os.O_WRONLY | os.O_CREAT)
    try:
        while True:
            os.write(fd, b"\0" * 4096)
    except OSError:
        pass
    finally:
        os.close(fd)


def test_the_last_status_on_a_full_disk_is_written_in_the_old_ones_space_or_left_out(small_fs):  # noqa: F811
    """Never a status file that says "running" after the run, never a .tmp beside it."""
    import json

    from spinefarm.storage.status import status_path, write_final_status, write_status

    run = small_fs / "run.h5"
    write_status(run, {"state": "running", "note": "x" * 3000})
    fill(small_fs)
    said = write_final_status(run, {"state": "done", "note": "y" * 3000})  # fits where the old one was
    assert said is not None and "No space left on device" in said and "rewritten" in said
    assert json.loads(status_path(run).read_text())["state"] == "done"
    said = write_final_status(run, {"state": "done", "note": "z" * 200_000})  # fits nowhere
    assert said is not None and "left out" in said
    assert not status_path(run).exists()
    assert sorted(p.name for p in small_fs.iterdir()) == ["filler"]
