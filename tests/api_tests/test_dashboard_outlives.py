"""A dashboard that outlives the search: the page after the search process exits, `search --serve`, and a run's
state read from its file alone (a copied file, a killed coordinator), in Chromium and over HTTP."""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import time
import urllib.request

import pytest

from tests.api_tests.test_dashboard_browser import ARTIFACTS, Server, free_port
from tests.coordinator_tests.helpers import wait_for
from tests.coordinator_tests.procs import ROOT

pytestmark = pytest.mark.integration


def get(url: str) -> dict:
    with urllib.request.urlopen(url, timeout=30) as r:
        return json.loads(r.read())


def search(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "spinefarm", "search", "sphere:3", "--workers", "1", "--quiet",
                             *args], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_the_page_keeps_its_data_after_the_search_exits(browser, tmp_path):
    port = free_port()
    out = tmp_path / "ends.h5"
    proc = search("--trials", "300", "--duration", "0.1", "--out", str(out), "--run-id", "ends-view",
                  "--api-port", str(port))
    try:
        page = _live_page(browser, proc, f"http://127.0.0.1:{port}", "ends-view")
        assert page.locator("#live").is_visible()
        proc.wait(120)  # the search ends, its server with it
        page.wait_for_selector("#ended", timeout=30_000)
        assert f"spinefarm api {out}" in page.locator("#ended").inner_text()
        assert not page.locator("#live").is_visible()
        # what the page showed is still there
        assert page.locator("#trial-table tr.row").count() > 0
        assert page.locator("#plot-progress .scatterlayer .trace path.point").count() > 0
        page.screenshot(path=ARTIFACTS / "run-after-search-ended.png", full_page=True)
        page.close()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(30)
    assert proc.returncode == 0, proc.stderr.read()


def test_a_page_that_saw_its_run_end_still_notices_its_server_go(browser, tmp_path):
    """The page reads the search's last status (done) while its server is still up, then the server stops: the
    page must still say so (the race of a search that ends, as `--serve` holds it open on purpose here)."""
    port = free_port()
    out = tmp_path / "watched.h5"
    proc = search("--trials", "150", "--duration", "0.1", "--out", str(out), "--run-id", "watched",
                  "--api-port", str(port), "--serve")
    try:
        page = _live_page(browser, proc, f"http://127.0.0.1:{port}", "watched")
        page.wait_for_selector("#run-title .state.done", timeout=120_000)  # the page has seen the run end
        assert proc.poll() is None and not page.locator("#ended").count()
        proc.send_signal(signal.SIGINT)
        assert proc.wait(30) == 0
        page.wait_for_selector("#ended", timeout=30_000)
        assert f"spinefarm api {out}" in page.locator("#ended").inner_text()
        page.close()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(30)


def _live_page(browser, proc: subprocess.Popen, url: str, run_id: str):
    """The run's page on a running search's own dashboard, once it shows trials."""
    wait_for(lambda: _running(proc) and _answers(f"{url}/runs/{run_id}"), timeout_s=60, poll_s=0.2,
             what="the search's dashboard")
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    page.goto(f"{url}/#/run/{run_id}")
    page.wait_for_selector("#trial-table tr.row", timeout=60_000)
    return page


def _running(proc: subprocess.Popen) -> bool:
    """A search that exited early fails the wait at once, with what it said."""
    if proc.poll() is not None:
        raise AssertionError(f"the search exited with {proc.returncode}: {proc.stderr.read()}")
    return True


def _answers(url: str) -> bool:
    try:
        get(url if "/runs/" in url else url + "/health")
        return True
    except OSError:
        return False


def test_search_serve_keeps_the_dashboard_up_until_ctrl_c(tmp_path):
    port = free_port()
    out = tmp_path / "served.h5"
    proc = search("--trials", "20", "--out", str(out), "--run-id", "served", "--api-port", str(port), "--serve")
    try:
        url = f"http://127.0.0.1:{port}"
        wait_for(lambda: _answers(url) and get(url + "/runs/served")["state"] == "done", timeout_s=120, poll_s=0.2,
                 what="the finished run on the dashboard")
        time.sleep(1.0)
        assert proc.poll() is None  # the search is over, the dashboard is still up
        status = get(url + "/runs/served")
        assert status["trials_done"] == 20 and status["reopen_command"] == f"spinefarm api {out}"
        proc.send_signal(signal.SIGINT)
        assert proc.wait(30) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(30)
    stdout, stderr = proc.communicate()
    assert "stays up on" in stderr
    assert stdout.startswith("search done: 20 parameter sets, 20 evaluations of sphere:3")


def test_the_state_comes_from_the_file_alone(tmp_path):
    """A copied finished run shows done, a killed search shows stopped (with how to resume), no sidecar needed."""
    done = tmp_path / "done.h5"
    r = subprocess.run([sys.executable, "-m", "spinefarm", "search", "sphere:3", "--trials", "15", "--workers", "1",
                        "--out", str(done), "--run-id", "done-run", "--api-port", "-1", "--quiet"], cwd=ROOT,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    elsewhere = tmp_path / "copy"
    elsewhere.mkdir()
    shutil.copy(done, elsewhere / "done.h5")  # no status file, no lock file beside it
    killed = tmp_path / "killed.h5"
    proc = search("--trials", "100000", "--duration", "0.1", "--out", str(killed), "--run-id", "killed-run",
                  "--api-port", "-1")
    from spinefarm.storage.hdf5_reader import read_run

    wait_for(lambda: _running(proc) and killed.exists() and _finished(killed, read_run) >= 5, timeout_s=120,
             poll_s=0.2, what="a few results")
    port = free_port()
    s = Server(["api", str(elsewhere / "done.h5"), str(killed), "--port", str(port)], port)
    try:
        assert get(f"{s.url}/runs/killed-run")["state"] == "running"
        proc.kill()  # SIGKILL: its status file still says running
        proc.wait(30)
        status = get(f"{s.url}/runs/killed-run")
        assert status["state"] == "stopped" and status["eta_s"] is None
        assert status["resume_command"] == f"spinefarm search --resume {killed}"
        copied = get(f"{s.url}/runs/done-run")
        assert not (elsewhere / "done.h5.status.json").exists()
        assert copied["state"] == "done" and copied["trials_done"] == 15 and copied["resume_command"] is None
        assert copied["sampler"] == "cmaes" and copied["started_at_unix_s"] > 0
    finally:
        s.stop()
        if proc.poll() is None:
            proc.kill()
            proc.wait(30)


def _finished(path, read_run) -> int:
    try:
        _, cols = read_run(path)
    except Exception:
        return 0
    return int((cols["status"] != b"waiting").sum())
