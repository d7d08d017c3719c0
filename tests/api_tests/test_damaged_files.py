"""A damaged run file among healthy ones: left out quickly, never hanging the server or its shutdown."""

from __future__ import annotations

import shutil
import signal
import struct
import subprocess
import sys
import time

import httpx
import pytest

from tests.coordinator_tests.helpers import sphere_core, wait_for
from tests.coordinator_tests.procs import ROOT
from tests.coordinator_tests.test_core import ask, res, submit


def run_file(path, run_id):
    core, storage, _ = sphere_core(trials=400, out=path, run_id=run_id)
    for _ in range(5):
        grant = ask(core, n=64)
        submit(core, [(a.lease_id, res(a)) for a in grant.assignments])
    storage.close()


@pytest.fixture
def runs_dir(tmp_path):
    d = tmp_path / "runs"
    d.mkdir()
    run_file(d / "good.h5", "good")
    run_file(tmp_path / "src.h5", "damaged")
    for name in ("header.h5", "checksum.h5"):  # garbage in the metadata: an SWMR reader retries for ever
        shutil.copy(tmp_path / "src.h5", d / name)
        with open(d / name, "r+b") as fh:
            fh.seek(200)
            fh.write(b"\xff" * 512)
    mark_open_for_writing(d / "header.h5")  # with its writer's lock held (below): read as SWMR, to the deadline
    shutil.copy(tmp_path / "src.h5", d / "truncated.h5")
    with open(d / "truncated.h5", "r+b") as fh:
        fh.truncate((d / "truncated.h5").stat().st_size // 2)
    (d / "junk.h5").write_bytes(b"\x00" * 100)
    return d


def mark_open_for_writing(path):
    """Set the superblock's "open for writing" flags (write, SWMR write), as a live writer has them."""
    from spinefarm.storage.probe import lookup3

    with open(path, "r+b") as fh:
        head = bytearray(fh.read(48))
        head[11] = 0x05
        head[44:48] = struct.pack("<I", lookup3(bytes(head[:44])))
        fh.seek(0)
        fh.write(head)


def test_damaged_files_are_left_out_and_sigterm_stops_the_server(runs_dir):
    from spinefarm.cli.service_commands import free_port
    from spinefarm.storage.runlock import RunLock

    writer = RunLock(runs_dir / "header.h5").acquire()  # a coordinator has header.h5 open
    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "spinefarm", "api", "--runs-dir", str(runs_dir), "--port",
                             str(port)], cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        url = f"http://127.0.0.1:{port}"
        wait_for(lambda: _ok(url + "/health"), timeout_s=30, what="the API")
        t0 = time.monotonic()
        runs = httpx.get(url + "/runs", timeout=30).json()
        assert [r["run_id"] for r in runs] == ["good"]
        assert time.monotonic() - t0 < 15  # the hanging live file costs one probe deadline (5 s), once
        t0 = time.monotonic()
        for _ in range(3):  # known-bad files are not probed again
            assert httpx.get(url + "/runs/good", timeout=5).status_code == 200
            assert httpx.get(url + "/runs", timeout=5).status_code == 200
        assert time.monotonic() - t0 < 5
        assert httpx.get(url + "/runs/damaged", timeout=5).status_code == 404
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(15) in (0, -signal.SIGTERM)  # uvicorn re-raises the signal once it has stopped
        err = proc.stderr.read()
        assert "truncated" in err and "did not finish within 5 s" in err
        # a damaged file no writer has open is read once, not to the deadline, and HDF5 says what it found
        assert "checksum.h5: 'Unable to" in err and "metadata checksum" in err
        assert "checksum.h5 did not finish" not in err
    finally:
        writer.release()
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def _ok(url):
    try:
        return httpx.get(url, timeout=1).status_code == 200
    except httpx.HTTPError:
        return False


def test_a_status_file_with_a_lone_surrogate_is_served(tmp_path):
    """An old status file holding a worker id like "\\ud800" must not turn /runs into 500 for good."""
    from spinefarm.api.app import create_app
    from spinefarm.storage.status import status_path
    from tests.http_server import served

    run_file(tmp_path / "run.h5", "odd")
    status_path(tmp_path / "run.h5").write_text(
        '{"run_id": "odd", "state": "running", "workers": [{"worker_id": "\\ud800", "alive": true, "leases": 0, '
        '"last_contact_unix_s": 1.0}], "updated_at_unix_s": 1.0}')
    with served(create_app(runs_dir=tmp_path)) as client:
        assert client.get("/runs").status_code == 200
        assert client.get("/runs/odd").status_code == 200


# The probe's reading child, its read slowed (after it said it started, so the read's own deadline counts):
# 8 s the first time, 6 s after (longer than the first deadline of 5 s, shorter than the second of 10 s); a
# marker file counts the reads.
SLOW_FIRST_READ = """
import sys
import spinefarm.storage.probe as probe
READY = "print('ready', flush=True)\\n"
probe._PROBE_CODE = probe._PROBE_CODE.replace(READY, READY + (
    "import os, time\\n"
    "marker = sys.argv[1] + '.first-read'\\n"
    "first = not os.path.exists(marker)\\n"
    "open(marker, 'w').close()\\n"
    "time.sleep(8 if first else 6)\\n"))
"""


def test_a_file_read_too_slowly_once_is_served_when_read_again(tmp_path):
    """Out of time is not damaged: the file is read again in the background with a longer deadline, and
    served from then on, while requests keep answering at once."""
    from spinefarm.cli.service_commands import free_port

    d = tmp_path / "runs"
    d.mkdir()
    run_file(d / "slow.h5", "slow")
    port = free_port()
    args = ["api", "--runs-dir", str(d), "--port", str(port)]
    proc = subprocess.Popen([sys.executable, "-c", SLOW_FIRST_READ + f"from spinefarm.cli.main import main\n"
                             f"sys.exit(main({args!r}))"], cwd=ROOT, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    try:
        url = f"http://127.0.0.1:{port}"
        wait_for(lambda: _ok(url + "/health"), timeout_s=30, what="the API")
        assert httpx.get(url + "/runs", timeout=30).json() == []  # the first read ran out of time (5 s)
        t0 = time.monotonic()

        def listed() -> bool:
            t = time.monotonic()
            runs = httpx.get(url + "/runs", timeout=30).json()
            assert time.monotonic() - t < 3, "a request waited on the background read"
            return [r["run_id"] for r in runs] == ["slow"]

        wait_for(listed, timeout_s=60, poll_s=0.5, what="the slow file to be served")
        assert time.monotonic() - t0 >= 4  # read again after the back-off, not at once
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(30)
    err = proc.stderr.read()
    assert "did not finish within 5 s" in err and "machine was too busy" in err
