"""The HTTP status API over real run files; one test runs a real server process."""

from __future__ import annotations

import io
import re
import subprocess
import sys
import time

import h5py
import httpx
import numpy as np
import pytest

from spinefarm.api.app import create_app
from spinefarm.protocol.errors import ConfigError
from spinefarm.storage.hdf5 import Hdf5Storage
from spinefarm.storage.runlock import RunLock
from spinefarm.storage.status import write_status
from tests.coordinator_tests.helpers import wait_for
from tests.http_server import served
from tests.storage_tests.conftest import make_meta, result


def write_run(path, run_id="run-a", n=6, finished=4, keep_open=False):
    s = Hdf5Storage.create(path, make_meta(run_id))
    for i in range(n):
        u = np.full(3, i / 10)
        s.add_trial(i, u, 2 * u - 1, "monte_carlo" if i < 3 else "gaussian", -1 if i < 3 else 2, 100 + i)
    for i in range(finished):
        s.finish_trial(i, result(i, float(i % 3), seed=100 + i), float(i % 3))
    s.flush()
    if not keep_open:
        s.close()
    return s


@pytest.fixture
def client(tmp_path):
    write_run(tmp_path / "a.h5")
    lock = RunLock(tmp_path / "a.h5").acquire()  # a coordinator holds the file: the status file speaks for it
    write_status(tmp_path / "a.h5", {"state": "running", "trials_leased": 2, "trials_queued": 94,
                                      "rate_trials_s": 3.5, "eta_s": 27.0, "updated_at_unix_s": time.time(),
                                      "workers": [{"worker_id": "w-1", "alive": True, "leases": 2,
                                                   "last_contact_unix_s": time.time()}]})
    with served(create_app(runs_dir=tmp_path)) as c:
        yield c
    lock.release()


def test_runs_list_and_status(client):
    runs = client.get("/runs").json()
    assert [r["run_id"] for r in runs] == ["run-a"]
    st = client.get("/runs/run-a").json()
    assert (st["trials_done"], st["trials_complete"], st["trials_leased"], st["trials_queued"]) == (4, 4, 2, 94)
    assert st["state"] == "running" and st["rate_trials_s"] == 3.5 and st["eta_s"] == 27.0
    assert st["best"]["trial_id"] == 2 and st["workers"][0]["worker_id"] == "w-1"
    # one evaluation per parameter set: all three counts speak of the same trials
    assert (st["trials_budget"], st["trials_planned"], st["parameter_sets_sampled"]) == (100, 100, 6)


def test_meta_shows_the_run_instance_history(client):
    [created] = client.get("/runs/run-a/meta").json()["instances"]   # written once, never resumed
    assert created["how"] == "create" and re.fullmatch(r"\d{13}-[0-9a-f]{16}", created["instance"])
    assert abs(created["opened_at_unix_s"] - time.time()) < 600


def test_best_trials_have_named_parameters_and_every_score_part(client):
    best = client.get("/runs/run-a/best", params={"k": 3}).json()
    assert [b["trial_id"] for b in best] == [2, 1, 0]  # objective 2 > 1 > 0 (trial 3 ties 0, later id)
    b = best[0]
    assert b["params"] == pytest.approx({"p0": -0.6, "p1": -0.6, "p2": -0.6})
    assert b["params_unit"] == pytest.approx({"p0": 0.2, "p1": 0.2, "p2": 0.2})
    assert set(b["scores"]) >= {"distance_m", "speed_cm_s", "work_j", "cot", "ntrt_distance_cm", "wall_time_s"}
    assert b["scores"]["distance_m"] == 2.0 and b["phase"] == "monte_carlo" and b["parent"] is None


def test_one_trial_including_a_waiting_one(client):
    t = client.get("/runs/run-a/trials/5").json()
    assert (t["status"], t["phase"], t["parent"], t["seed"]) == ("waiting", "gaussian", 2, 105)
    assert t["scores"]["distance_m"] is None  # no result yet: null, not NaN


def test_trials_come_in_pages_of_one_status_or_all(client):
    page = client.get("/runs/run-a/trials", params={"offset": 1, "limit": 2}).json()
    assert (page["run_id"], page["status"], page["total"], page["offset"], page["limit"]) == ("run-a", None, 6, 1, 2)
    assert [t["trial_id"] for t in page["trials"]] == [1, 2]
    assert page["trials"][0] == client.get("/runs/run-a/trials/1").json()  # the same view as one trial's
    waiting = client.get("/runs/run-a/trials", params={"status": "waiting"}).json()
    assert (waiting["total"], [t["trial_id"] for t in waiting["trials"]]) == (2, [4, 5])
    assert client.get("/runs/run-a/trials", params={"status": "complete", "offset": 4}).json()["trials"] == []
    assert len(client.get("/runs/run-a/trials").json()["trials"]) == 6
    detail = client.get("/runs/run-a/trials", params={"status": "done"}).json()["detail"]
    assert detail["message"].startswith("query.status: Input should be 'waiting', 'running', 'complete' or "
                                        "'failed'; received 'done'")


def test_an_unknown_path_names_the_paths_there_are(client):
    r = client.get("/runs/run-a/trialz")
    assert r.status_code == 404
    message = r.json()["detail"]["message"]
    assert message.startswith("no such endpoint; received GET '/runs/run-a/trialz'; expected one of /runs, ")
    assert "/runs/{run_id}/trials/{trial_id}" in message and message.endswith("(described at /docs)")
    # a path that exists but names no run or trial says that instead
    assert client.get("/runs/run-a/trials/6").json()["detail"]["message"].startswith("no such trial")


@pytest.mark.parametrize(("url", "status", "code"), [
    ("/runs/nope", 404, "not_found"),
    ("/runs/run-a/trials/6", 404, "not_found"),
    ("/runs/run-a/trials/-1", 422, "invalid_query"),
    ("/runs/run-a/trials/abc", 422, "invalid_query"),
    ("/runs/run-a/trials/99999999999999999999999", 422, "invalid_query"),
    ("/runs/run-a/best?k=0", 422, "invalid_query"),
    ("/runs/run-a/best?k=1001", 422, "invalid_query"),
    ("/runs/run-a/best?k=NaN", 422, "invalid_query"),
    ("/runs/run-a/best?k=", 422, "invalid_query"),
    ("/runs/bad*id", 422, "invalid_query"),
    ("/runs/nope/best", 404, "not_found"),
    ("/runs/nope/file", 404, "not_found"),
    ("/nothing/here", 404, "not_found"),
])
def test_bad_queries_get_4xx_with_stable_details(client, url, status, code):
    r = client.get(url)
    assert r.status_code == status
    detail = r.json()["detail"]
    assert detail["code"] == code and isinstance(detail["message"], str) and detail["message"]


def test_error_detail_names_what_was_received(client):
    detail = client.get("/runs/run-a/best?k=0").json()["detail"]
    assert detail["message"] == "query.k: Input should be greater than or equal to 1; received '0'"
    detail = client.get("/runs/run-a/trials/6").json()["detail"]
    assert detail["message"] == "no such trial; received 6; expected 0 <= trial_id < 6"


def test_an_unknown_query_parameter_is_refused_by_name_and_pages_ignore_them(client):
    """A misspelt ?n=3 would otherwise answer with the default ten trials without a word."""
    r = client.get("/runs/run-a/best?n=3")
    assert r.status_code == 422
    assert r.json()["detail"] == {"code": "invalid_query", "message": "unknown query parameter for "
                                  "/runs/run-a/best; received ['n']; expected ['k']"}
    detail = client.get("/runs?limit=3&k=1").json()["detail"]
    assert detail["message"] == "unknown query parameter for /runs; received ['k', 'limit']; expected no query " \
                                "parameters"
    assert len(client.get("/runs/run-a/best?k=3").json()) == 3
    assert client.get("/?run=run-a").status_code == 200  # the dashboard page, as a shared link may carry it


def test_download_is_a_readable_snapshot(client):
    r = client.get("/runs/run-a/file")
    assert r.status_code == 200 and r.headers["content-type"] == "application/x-hdf5"
    with h5py.File(io.BytesIO(r.content), "r") as f:
        assert f.attrs["run_id"] == "run-a" and f["trials/distance_m"].shape == (6,)


def test_openapi_documents_every_endpoint(client):
    paths = client.get("/openapi.json").json()["paths"]
    assert {"/runs", "/runs/{run_id}", "/runs/{run_id}/best", "/runs/{run_id}/trials",
            "/runs/{run_id}/trials/{trial_id}", "/runs/{run_id}/file"} <= set(paths)


def test_stale_status_file_reads_as_stalled(tmp_path):
    """Silent while it still holds the file: stalled; once nothing holds it: stopped (the file's own state)."""
    write_run(tmp_path / "a.h5")
    write_status(tmp_path / "a.h5", {"state": "running", "updated_at_unix_s": time.time() - 3600})
    lock = RunLock(tmp_path / "a.h5").acquire()
    with served(create_app([tmp_path / "a.h5"])) as c:
        assert c.get("/runs/run-a").json()["state"] == "stalled"
        lock.release()
        st = c.get("/runs/run-a").json()
        assert st["state"] == "stopped" and st["workers"] == [] and st["eta_s"] is None
        assert st["resume_command"] == f"spinefarm search --resume {tmp_path / 'a.h5'}"


def test_app_needs_something_to_serve():
    with pytest.raises(ConfigError, match="run files or a runs directory"):
        create_app()


@pytest.mark.integration
def test_real_server_reads_a_live_run_and_serves_snapshots(tmp_path):
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    writer = write_run(tmp_path / "live.h5", run_id="live", n=10, finished=2, keep_open=True)
    proc = subprocess.Popen([sys.executable, "-m", "spinefarm", "api", "--runs-dir", str(tmp_path),
                             "--port", str(port)], stderr=subprocess.DEVNULL)
    base = f"http://127.0.0.1:{port}"
    try:
        def up():
            try:
                return httpx.get(f"{base}/health", timeout=1.0).status_code == 200
            except httpx.TransportError:
                return False
        wait_for(up, timeout_s=30, poll_s=0.1, what="the API server")
        assert httpx.get(f"{base}/runs/live").json()["trials_done"] == 2
        writer.finish_trial(7, result(7, 42.0, seed=107), 42.0)  # the run goes on while served
        writer.flush()
        # a run's status is read once per interval for every request (api.registry.VIEW_INTERVAL_S): seen next
        wait_for(lambda: httpx.get(f"{base}/runs/live").json()["trials_done"] == 3, timeout_s=5, poll_s=0.2,
                 what="the new row in the run's status")
        assert httpx.get(f"{base}/runs/live").json()["best"]["trial_id"] == 7
        r = httpx.get(f"{base}/runs/live/file")
        with h5py.File(io.BytesIO(r.content), "r") as f:
            assert f["trials/distance_m"][7] == 42.0
        for bad in ("/runs/live/best?k=-5", "/runs/live/trials/10", "/runs/x%00y", "/runs/live/best?k=1e9"):
            assert 400 <= httpx.get(base + bad).status_code < 500, bad
    finally:
        proc.terminate()
        proc.wait(10)
        writer.close()


def test_verification_verdicts_show_and_a_not_reproduced_best_is_skipped(tmp_path):
    s = write_run(tmp_path / "v.h5", run_id="run-v", keep_open=True)
    s.set_verification(2, "not_reproduced", 0.4, "not reproduced: finer step run moved 0.4 m against 2 m")
    s.set_verification(1, "holds", 0.98)
    s.flush()
    s.close()
    with served(create_app(runs_dir=tmp_path)) as c:
        best = c.get("/runs/run-v/best", params={"k": 2}).json()
        assert [b["trial_id"] for b in best] == [1, 0]  # trial 2 had the top objective but did not hold
        v = best[0]["verification"]
        assert {k: v[k] for k in ("verdict", "label", "fine_step_distance_m", "judge_distance_m", "reason", "judge")} \
            == {"verdict": "holds", "label": "holds", "fine_step_distance_m": 0.98, "judge_distance_m": 0.98,
                "reason": None, "judge": "the search's engine at a finer step"}
        t2 = c.get("/runs/run-v/trials/2").json()
        assert t2["verification"]["verdict"] == "not_reproduced" and "finer step" in t2["verification"]["reason"]
        assert c.get("/runs/run-v/trials/3").json()["verification"]["verdict"] == "not_checked"
