"""The run file under faults: one writer, acknowledged means synced to the disk (a full disk, a disk
that dies mid-run), damaged or read-only files refused."""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from spinefarm.coordinator.setup import resume_run
from spinefarm.protocol.errors import StorageError
from spinefarm.storage.hdf5_reader import read_run
from spinefarm.storage.status import read_status
from tests.coordinator_tests.helpers import free_endpoint, sphere_core
from tests.coordinator_tests.procs import ROOT, coordinator, stop, wait_status
from tests.coordinator_tests.test_core import ask, res, submit


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def finished_run(path: Path, n: int = 12) -> None:
    core, storage, _ = sphere_core(trials=40, out=path)
    grant = ask(core, n=n)
    submit(core, [(a.lease_id, res(a, distance=0.1 * a.trial_id)) for a in grant.assignments])
    storage.close()


def test_a_second_writer_is_refused_also_with_overwrite_and_resume(tmp_path):
    path = tmp_path / "run.h5"
    _, storage, _ = sphere_core(out=path)
    try:
        for attempt in (lambda: sphere_core(out=path, run_id="other"),
                        lambda: resume_run(path)):
            with pytest.raises(StorageError, match="another coordinator"):
                attempt()
        from spinefarm.coordinator.problem import build_run_config
        from spinefarm.coordinator.setup import SearchSettings, new_run

        with pytest.raises(StorageError, match=f"pid {os.getpid()}"):
            new_run(build_run_config("other", "sphere:4"), SearchSettings(trials=5), path, overwrite=True)
        assert read_run(path)[0].run_id == "test-run"
    finally:
        storage.close()
    # Released on close: the next writer gets it.
    _, storage2 = resume_run(path)
    storage2.close()


def test_a_live_coordinator_process_keeps_its_file_against_search_overwrite_and_resume(tmp_path):
    path, ep = tmp_path / "run.h5", free_endpoint()
    first = coordinator(ep, path, "sphere:3", "--trials", "100000", "--run-id", "first")
    try:
        wait_status(path, lambda st: st["state"] == "running", "the first coordinator")
        before = digest(path)
        for args in (("search", "sphere:3", "--trials", "10", "--workers", "0", "--out", str(path), "--overwrite",
                      "--api-port", "-1", "--run-id", "second"),
                     ("search", "--resume", str(path), "--workers", "0", "--api-port", "-1")):
            r = subprocess.run([sys.executable, "-m", "spinefarm", *args], cwd=ROOT, capture_output=True, text=True,
                               timeout=60)
            assert r.returncode == 2, r.stderr
            assert "being written by another coordinator" in r.stderr and f"pid {first.pid}" in r.stderr
        assert digest(path) == before and first.poll() is None
        assert read_run(path)[0].run_id == "first"
    finally:
        stop(first)


def damage(path: Path, rows: dict[str, tuple[int, object]]) -> None:
    with h5py.File(path, "r+") as f:
        for column, (row, value) in rows.items():
            f["trials"][column][row] = value


def test_resume_validates_every_row_and_refuses_a_damaged_file_untouched(tmp_path):
    path = tmp_path / "run.h5"
    finished_run(path)
    damage(path, {"status": (3, b"c\xffmpl"), "distance_m": (5, np.nan), "seed": (7, 12345),
                  "trial_id": (8, 99), "params_unit": (9, [0.5, 2.0, 0.5, 0.5])})
    before = digest(path)
    with pytest.raises(StorageError) as err:
        resume_run(path)
    msg = str(err.value)
    assert "5 of 12 stored rows are invalid" in msg
    for what in ("status not one of", "row 3", "non-finite distance_m", "row 5", "seed is not", "row 7",
                 "trial id is not the row number", "row 8", "outside [0, 1]", "row 9"):
        assert what in msg, what
    assert digest(path) == before
    # An undamaged file resumes.
    good = tmp_path / "good.h5"
    finished_run(good)
    core, storage = resume_run(good)
    assert core.study.n_finished == 12
    storage.close()


def test_a_read_only_run_file_stays_read_only(tmp_path):
    path = tmp_path / "run.h5"
    finished_run(path)
    path.chmod(0o444)
    before = digest(path)
    with pytest.raises(StorageError, match="read-only"):
        resume_run(path)
    assert digest(path) == before and (path.stat().st_mode & 0o777) == 0o444


# --- a file system that fills up (a real tmpfs of a few hundred kB) -----------------------------------
@pytest.fixture
def small_fs(tmp_path):
    mnt = tmp_path / "fs"
    mnt.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1200k", "tmpfs", str(mnt)], capture_output=True,
                       text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs to fill up (needs root): {r.stderr.strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


_DRIVER = """
import json, os, sys
from tests.coordinator_tests.helpers import sphere_core
from tests.coordinator_tests.test_core import ask, res, submit
core, storage, clock = sphere_core(trials=10**6, out=sys.argv[1])
acked, unanswered = [], 0
for _ in range(10**5):
    grant = ask(core, n=64)
    from spinefarm.protocol.envelope import encode_message
    from spinefarm.protocol.submissions import ResultSubmission, SubmittedResult
    items = tuple(SubmittedResult(a.lease_id, res(a)) for a in grant.assignments)
    reply = core.handle_results(encode_message(ResultSubmission("w1", items)))
    if reply is None:
        unanswered += 1
        break
    from spinefarm.protocol.envelope import decode_message
    from spinefarm.protocol.submissions import ResultAck
    acked += [t for t, v in decode_message(reply, ResultAck).verdicts if v.value == "stored"]
later = [core.handle_work(b"{}") is None, core.handle_results(b"{}") is None]
print(json.dumps({"acked": acked, "failure": core.write_failure, "silent_after": later}), flush=True)
os._exit(0)
"""


def test_a_full_disk_stops_acknowledging_and_the_file_holds_every_acknowledged_result(small_fs):
    path = small_fs / "run.h5"
    r = subprocess.run([sys.executable, "-c", _DRIVER, str(path)], cwd=ROOT, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    import json

    out = json.loads(r.stdout)
    assert "No space left on device" in out["failure"] and out["silent_after"] == [True, True]
    assert len(out["acked"]) > 500
    _, cols = read_run(path)
    stored = set(np.flatnonzero(cols["status"] == b"complete").tolist())
    assert set(out["acked"]) <= stored


def test_search_on_a_full_disk_exits_non_zero_saying_why(small_fs):
    path = small_fs / "run.h5"
    r = subprocess.run([sys.executable, "-m", "spinefarm", "search", "sphere:8", "--trials", "1000000", "--workers",
                        "1", "--batch", "64", "--out", str(path), "--api-port", "-1", "--quiet"], cwd=ROOT,
                       capture_output=True, text=True, timeout=180)
    assert r.returncode == 1, r.stderr[-2000:]
    assert "No space left on device" in r.stderr and "--resume" in r.stderr
    assert "Segmentation" not in r.stderr
    _, cols = read_run(path)
    assert np.count_nonzero(cols["status"] == b"complete") > 500
    st = read_status(path)
    assert st is None or st["state"] in ("running", "failed")


# --- a disk that dies under a writing coordinator (a real ext4 on a loop device) --------------------
def test_a_disk_that_dies_mid_run_leaves_every_acknowledged_result_on_it(tmp_path):
    """The coordinator process writes to an ext4 image that is shut down without flushing its journal
    (a power cut, as the kernel sees it) once its workers hold 300 acknowledgements. It must exit 1
    naming the I/O error; after a remount the file holds every acknowledged result with its distance
    (what fsync before acknowledging guarantees: without it the file is lost entirely) and resumes."""
    from bench.faults import power_cut
    from tests.ext4_image import Ext4Image

    why = Ext4Image.unavailable()
    if why is not None:
        pytest.skip(f"no ext4 image to shut down: {why}")
    fig = power_cut(tmp_path, workers=2, cut_after_acks=300)
    if "skipped" in fig:
        pytest.skip(f"no ext4 image to shut down: {fig['skipped']}")
    assert not fig["hung"] and fig["seconds_to_exit"] < 30, fig
    assert fig["exit_code"] == 1 and fig["says_why"], fig
    assert fig["acknowledged"] >= 300 and "unreadable" not in fig, fig
    assert fig["lost"] == 0 and fig["duplicated"] == 0, fig
    assert fig["complete_in_file"] >= fig["acknowledged"], fig
    assert fig["resumes"] == "yes", fig  # and the run continues from it (every row validated)
