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
