"""The dashboard in a real browser (Playwright + Debian's chromium) over run files written by real searches.

Screenshots land in tests/artifacts/ (git-ignored) for a person to look at.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from spinefarm.storage.hdf5_reader import read_run
from tests.coordinator_tests.helpers import wait_for
from tests.coordinator_tests.procs import ROOT

pytestmark = pytest.mark.integration

ARTIFACTS = ROOT / "tests" / "artifacts"


def chromium_path() -> str:
    path = os.environ.get("SPINEFARM_CHROMIUM") or shutil.which("chromium") or shutil.which("chromium-browser")
    if not path:
        pytest.fail("no chromium found: `make test` installs Debian's chromium (apt-get install chromium)")
    return path


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def spinefarm(*args: str) -> subprocess.CompletedProcess:
    r = subprocess.run([sys.executable, "-m", "spinefarm", *args], cwd=ROOT, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    return r


class Server:
    """`spinefarm api` (or `spinefarm search`) as a real process; `url` once it answers."""

    def __init__(self, args: list[str], port: int, prelude: str | None = None) -> None:
        cmd = [sys.executable, "-m", "spinefarm", *args] if prelude is None else [
            sys.executable, "-c", prelude + f"; from spinefarm.cli.main import main; sys.exit(main({args!r}))"]
        self.proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        self.url = f"http://127.0.0.1:{port}"

        def up() -> bool:
            assert self.proc.poll() is None, self.proc.stderr.read()
            try:
                with urllib.request.urlopen(self.url + "/health", timeout=1):
                    return True
            except OSError:
                return False

        wait_for(up, timeout_s=60, poll_s=0.1, what="the API to answer")

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
        self.proc.wait(30)


FAILURES = {"diverged": 3, "error": 1}  # reasons are grouped by what precedes the first colon


def write_failing_run(path: Path) -> None:
    """A run file with failed trials (what a real search writes when trials diverge or raise)."""
    from spinefarm.protocol.states import TrialStatus
    from spinefarm.storage.hdf5 import Hdf5Storage
    from tests.storage_tests.conftest import make_meta, result

    s = Hdf5Storage.create(path, make_meta("failing-view", n_params=3))
    reasons = ["", "diverged: NaN in poses", "", "diverged: energy runaway", "error: ValueError: boom",
               "diverged: left its bounds", ""]
    for i, reason in enumerate(reasons):
        u = np.full(3, (i + 1) / 10)
        s.add_trial(i, u, 2 * u - 1, "monte_carlo", -1, i)
        status = TrialStatus.FAILED if reason else TrialStatus.COMPLETE
        s.finish_trial(i, result(i, i / 10, status=status, reason=reason, seed=i), i / 10 if not reason else np.nan)
    s.close()


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("runs")
    spinefarm("search", "sphere:9", "--trials", "300", "--workers", "1", "--out", str(d / "sphere.h5"),
              "--run-id", "sphere-view", "--api-port", "-1", "--quiet", "--seed", "3")
    spinefarm("search", "sphere:200", "--trials", "80", "--workers", "1", "--out", str(d / "wide.h5"),
              "--run-id", "wide-view", "--api-port", "-1", "--quiet")
    write_failing_run(d / "failing.h5")
    spinefarm("search", "tetraspine", "--engine", "bullet", "--trials", "3", "--workers", "1", "--duration", "1",
              "--out", str(d / "tetra.h5"), "--run-id", "tetra-view", "--api-port", "-1", "--quiet")
    return d


@pytest.fixture(scope="module")
def server(runs, tmp_path_factory):
    port = free_port()
    s = Server(["api", "--runs-dir", str(runs), "--port", str(port)], port)
    yield s
    s.stop()


@pytest.fixture
def page(browser, server):
    ctx = browser.new_context(viewport={"width": 1400, "height": 900}, accept_downloads=True)
    pg = ctx.new_page()
    pg.requests = []
    pg.errors = []
    pg.on("request", lambda r: pg.requests.append(r.url))
    # a request the page's Content-Security-Policy stopped never left the browser
    pg.on("requestfailed", lambda r: r.failure == "csp" and pg.requests.remove(r.url))
    pg.on("pageerror", lambda e: pg.errors.append(str(e)))
    yield pg
    assert not pg.errors, pg.errors
    ctx.close()


def points(page, plot_id: str, trace: int = 0) -> int:
    """Markers the browser actually drew in one trace of a plot."""
    return page.evaluate(f"""() => {{
        const t = document.querySelectorAll('#{plot_id} .scatterlayer .trace')[{trace}];
        return t ? t.querySelectorAll('path.point').length : -1; }}""")


def test_runs_page_lists_every_run_file(page, server):
    page.goto(server.url + "/")
    page.wait_for_selector("#runs-table tr.row >> nth=3")
    rows = page.locator("#runs-table tr.row")
    shown = sorted(rows.nth(i).get_attribute("data-run") for i in range(rows.count()))
    assert shown == ["failing-view", "sphere-view", "tetra-view", "wide-view"]
    page.screenshot(path=ARTIFACTS / "runs.png", full_page=True)
    assert all(u.startswith(server.url) for u in page.requests), page.requests


def test_run_page_plots_every_stored_trial(page, server, runs):
    _, cols = read_run(runs / "sphere.h5")
    complete = cols["status"] == b"complete"
    n_complete = int(complete.sum())
    front = int((cols["pareto_front"] == 1).sum())  # the run file marks its Pareto front
    page.goto(server.url + "/#/run/sphere-view")
    page.wait_for_selector("#trial-table tr.row")
    wait_for(lambda: page.locator("#plot-pareto .scatterlayer .trace").count() == 2, timeout_s=30, poll_s=0.1,
             what="the Pareto plot")
    assert n_complete == 300
    assert points(page, "plot-progress") == n_complete     # every trial's objective
    # speed against COT: every complete trial with both finite (a trial that did not move has an
    # infinite COT; the page says how many it leaves out)
    plottable = int((complete & np.isfinite(cols["speed_cm_s"]) & np.isfinite(cols["cot"])).sum())
    assert points(page, "plot-pareto") == plottable
    left_out = n_complete - plottable
    assert page.locator("#pareto-note").inner_text() == (f"{left_out} without a finite COT not shown" if left_out
                                                         else "")
    assert points(page, "plot-pareto", 1) == front >= 1
    assert points(page, "plot-param") == n_complete
    assert page.locator("#trials").get_attribute("data-rows") == str(len(cols["trial_id"]))
    assert page.locator("#trial-table tr.row").count() == min(200, len(cols["trial_id"]))
    # importance ranks all 9 parameters, the per-parameter selector offers them all
    assert page.locator("#param-select option").count() == 9
    assert page.locator("#plot-importance .bars path").count() == 9
    page.screenshot(path=ARTIFACTS / "run-sphere.png", full_page=True)
    # sorting by objective puts the best trial first
    page.click("#trial-table th[data-key=objective]")
    first = int(page.locator("#trial-table tr.row").first.get_attribute("data-trial"))
    assert first == int(np.nanargmax(np.where(complete, cols["objective"], np.nan)))
    assert all(u.startswith(server.url) for u in page.requests), [u for u in page.requests
                                                                 if not u.startswith(server.url)]


def test_a_click_on_a_trial_opens_it(page, server, runs):
    meta, cols = read_run(runs / "sphere.h5")
    page.goto(server.url + "/#/run/sphere-view")
    page.wait_for_selector("#trial-table tr.row")
    page.locator("#trial-table tr.row").nth(7).click()
    page.wait_for_selector("#trial-title")
    assert page.locator("#trial-title").inner_text().startswith("Trial 7")
    names = [page.locator("#params tbody tr").nth(i).locator("td").first.inner_text()
             for i in range(page.locator("#params tbody tr").count())]
    assert names == list(meta.param_names)
    shown = float(page.locator("#scores tr", has_text="distance_m").locator("td").nth(1).inner_text())
    assert shown == pytest.approx(cols["distance_m"][7], rel=1e-5)
    with page.expect_download() as dl:
        page.click("#dl-params")
    params = json.loads(Path(dl.value.path()).read_text())
    assert params["params"] == pytest.approx(dict(zip(meta.param_names, cols["params"][7], strict=True)))
    page.screenshot(path=ARTIFACTS / "trial-sphere.png", full_page=True)


def test_the_gait_picture_of_a_physics_trial(page, server, runs):
    _, cols = read_run(runs / "tetra.h5")
    page.goto(server.url + "/#/run/tetra-view/trial/0")
    page.wait_for_selector("#gait", timeout=240_000)
    assert page.evaluate("document.getElementById('gait').naturalWidth") > 400
    assert page.locator("#verification").inner_text().count("distance") == 2
    cards = page.locator(".cards").inner_text()
    assert "bullet" in cards and f"{cols['dt_s'][0] * 1000:g} ms" in cards  # the step this trial ran with
    page.screenshot(path=ARTIFACTS / "trial-tetraspine.png", full_page=True)
    page.goto(server.url + "/#/run/tetra-view")
    page.wait_for_selector("#trial-table tr.row")
    assert points(page, "plot-pareto") == int((cols["status"] == b"complete").sum())
    page.screenshot(path=ARTIFACTS / "run-tetraspine.png", full_page=True)


def test_without_the_simulator_the_picture_says_so(browser, runs):
    port = free_port()
    s = Server(["api", str(runs / "tetra.h5"), "--port", str(port)], port,
               prelude="import sys; sys.modules['pybullet'] = None")  # as if pybullet were not installed
    try:
        page = browser.new_page()
        page.goto(s.url + "/#/run/tetra-view/trial/1")
        page.wait_for_selector("#picture-error")
        assert "simulator is not installed" in page.locator("#picture-error").inner_text()
        assert page.locator("#params tbody tr").count() > 0  # everything else is served
        page.close()
    finally:
        s.stop()


def test_a_running_search_page_updates(browser, tmp_path):
    port = free_port()
    out = tmp_path / "live.h5"
    s = Server(["search", "sphere:3", "--trials", "60", "--workers", "1", "--duration", "0.1", "--out", str(out),
                "--run-id", "live-view", "--api-port", str(port), "--quiet"], port)
    try:
        page = browser.new_page(viewport={"width": 1400, "height": 900})
        page.goto(s.url + "/#/run/live-view")
        page.wait_for_selector("#trial-table tr.row")
        assert page.locator("#live").is_visible()
        first = int(page.locator("#trials").get_attribute("data-rows"))
        wait_for(lambda: int(page.locator("#trials").get_attribute("data-rows")) > first, timeout_s=30, poll_s=0.2,
                 what="the page to show new trials")
        page.screenshot(path=ARTIFACTS / "run-live.png", full_page=True)
        later = points(page, "plot-progress")
        assert later > 0
        page.close()
    finally:
        s.stop()


def test_docs_and_redoc_load_only_local_assets(page, server):
    page.goto(server.url + "/docs")
    page.wait_for_selector(".swagger-ui .opblock")
    assert page.locator(".swagger-ui .opblock").count() >= 8
    page.screenshot(path=ARTIFACTS / "docs.png")
    page.goto(server.url + "/redoc")
    page.wait_for_selector("text=Status and results of gait searches", timeout=30_000)
    assert page.locator("[data-section-id]").count() >= 8
    page.screenshot(path=ARTIFACTS / "redoc.png")
    foreign = [u for u in page.requests if not (u.startswith(server.url) or u.startswith(("blob:", "data:")))]
    assert not foreign, foreign


def test_two_hundred_parameters_stay_readable(page, server):
    page.goto(server.url + "/#/run/wide-view")
    page.wait_for_selector("#trial-table tr.row")
    wait_for(lambda: page.locator("#plot-importance .bars path").count() == 30, timeout_s=30, poll_s=0.1,
             what="the importance plot")
    assert page.locator("#importance-note").inner_text() == "the 30 strongest of 200 parameters"
    assert page.locator("#param-select option").count() == 200
    # parallel coordinates: the 8 most important parameters and the objective; the axes' list offers all 200
    assert page.locator("#pc-svg .pc-axis").count() == 9
    assert page.locator("#pc-axes input").count() == 200
    page.select_option("#param-select", "x123")
    wait_for(lambda: "x123" in page.locator("#plot-param .xtitle").text_content(), timeout_s=10, poll_s=0.1,
             what="the chosen parameter's plot")
    assert points(page, "plot-param") == 80
    page.screenshot(path=ARTIFACTS / "run-200-parameters.png", full_page=True)


def test_failed_trials_by_reason(page, server):
    page.goto(server.url + "/#/run/failing-view")
    page.wait_for_selector("#trial-table tr.row")
    wait_for(lambda: page.locator("#plot-failed .bars path").count() == len(FAILURES), timeout_s=30, poll_s=0.1,
             what="the failures plot")
    assert page.locator("#plot-failed").get_attribute("data-points") == str(sum(FAILURES.values()))
    labels = page.locator("#plot-failed .xtick").all_text_contents()
    assert labels == list(FAILURES)  # most frequent first
    page.click("#trial-table th[data-key=status]")
    assert page.locator("#trial-table tr.row").first.locator("td").nth(1).inner_text() == "failed"
    page.screenshot(path=ARTIFACTS / "run-failures.png", full_page=True)
