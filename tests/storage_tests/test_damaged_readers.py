"""Every reader of a damaged run file gives one clear error in bounded time; stored bytes never break decoding."""

from __future__ import annotations

import shutil
import subprocess
import sys
import time

import h5py
import httpx
import pytest

from tests.coordinator_tests.helpers import sphere_core, wait_for
from tests.coordinator_tests.procs import ROOT
from tests.coordinator_tests.test_core import ask, res, submit

BAD_TEXT = b"\xff\xfe\xc3("  # not UTF-8


def run_file(path, run_id):
    core, storage, _ = sphere_core(trials=100, out=path, run_id=run_id)
    grant = ask(core, n=20)
    submit(core, [(a.lease_id, res(a, distance=0.1 * a.trial_id)) for a in grant.assignments])
    storage.close()


@pytest.fixture
def files(tmp_path):
    good, bad = tmp_path / "good.h5", tmp_path / "bad.h5"
    run_file(good, "good")
    shutil.copy(good, bad)
    with open(bad, "r+b") as fh:  # 200 bytes of metadata overwritten at offset 96
        fh.seek(96)
        fh.write(b"\xa5" * 200)
    return good, bad


def test_load_run_on_a_damaged_file_raises_one_clear_error_in_bounded_time(files):
    _, bad = files
    code = ("import sys, spinefarm\nfrom spinefarm.protocol.errors import StorageError\n"
            "try:\n    spinefarm.load_run(sys.argv[1])\nexcept StorageError as exc:\n    print('ERR', exc)\n")
    t0 = time.monotonic()
    r = subprocess.run([sys.executable, "-c", code, str(bad)], capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert r.stdout.startswith("ERR") and "bad.h5" in r.stdout, (r.stdout, r.stderr)
    # no writer has it open: read once, HDF5's finding reported, no deadline waited out
    assert "metadata checksum" in r.stdout and "did not finish" not in r.stdout, r.stdout
    assert time.monotonic() - t0 < 30


def test_api_given_a_bad_and_a_good_file_serves_the_good_one(files):
    from spinefarm.cli.service_commands import free_port

    good, bad = files
    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "spinefarm", "api", str(bad), str(good), "--port", str(port)],
                            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        url = f"http://127.0.0.1:{port}"
        wait_for(lambda: _ok(url + "/health"), timeout_s=40, what="the API")
        assert [r["run_id"] for r in httpx.get(url + "/runs", timeout=30).json()] == ["good"]
    finally:
        proc.terminate()
        _, err = proc.communicate(timeout=20)
    assert f"skipping {bad}" in err, err


def _ok(url):
    try:
        return httpx.get(url, timeout=2).status_code == 200
    except httpx.HTTPError:
        return False


def _garble(path):
    with h5py.File(path, "r+") as f:
        g = f["trials"]
        best = int(g["distance_m"][:20].argmax())
        for col in ("worker_id", "reason", "verification"):
            g[col][best] = BAD_TEXT
        g["status"][3] = BAD_TEXT
    return best


def test_invalid_utf8_in_stored_cells_gives_no_500_and_no_traceback(files, tmp_path):
    from spinefarm.api.app import create_app
    from tests.http_server import served

    good, _ = files
    best = _garble(good)
    with served(create_app([good])) as c:
        for url in ("/runs/good/best?k=5", f"/runs/good/trials/{best}", "/runs/good/trials/3",
                    "/runs/good/trials.csv", "/runs", "/runs/good"):
            r = c.get(url)
            assert r.status_code == 200, (url, r.status_code, r.text[:300])
    out = tmp_path / "t.csv"
    r = subprocess.run([sys.executable, "-m", "spinefarm", "export", str(good), "--csv", str(out), "--best", "3"],
                       cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    assert "\ufffd" in out.read_text()
    import spinefarm

    df = spinefarm.load_run(good)
    assert "\ufffd" in df.loc[best, "worker_id"]


def test_export_of_a_damaged_file_gives_one_line(files, tmp_path):
    _, bad = files
    r = subprocess.run([sys.executable, "-m", "spinefarm", "export", str(bad), "--csv", str(tmp_path / "x.csv")],
                       cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode != 0 and "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_a_405_names_what_is_allowed_and_trials_csv_is_documented_as_csv(files):
    from spinefarm.api.app import create_app
    from tests.http_server import served

    good, _ = files
    with served(create_app([good])) as c:
        r = c.post("/runs")
        assert r.status_code == 405 and r.headers.get("allow") == "GET", dict(r.headers)
        spec = c.get("/openapi.json").json()
        content = spec["paths"]["/runs/{run_id}/trials.csv"]["get"]["responses"]["200"]["content"]
        assert list(content) == ["text/csv"], content


_KILLED_WRITER = """
import os, sys
from tests.coordinator_tests.helpers import sphere_core
from tests.coordinator_tests.test_core import ask, res, submit
core, storage, _ = sphere_core(trials=12, out=sys.argv[1])
grant = ask(core, n=12)
submit(core, [(a.lease_id, res(a)) for a in grant.assignments])
assert core.done
os._exit(0)  # as a SIGKILL after the last result: the file is never closed
"""


def test_a_finished_file_of_a_killed_coordinator_opens_plain_once_spinefarm_has_read_it(tmp_path):
    path = tmp_path / "run.h5"
    r = subprocess.run([sys.executable, "-c", _KILLED_WRITER, str(path)], cwd=ROOT, capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 0, r.stderr
    with pytest.raises(OSError):
        h5py.File(path, "r").close()  # "already open for write": HDF5's flags of the killed writer
    import spinefarm

    assert len(spinefarm.load_run(path)) == 12
    with h5py.File(path, "r") as f:
        assert f["trials"]["status"].shape[0] >= 12
