"""The views a user of a sweep dashboard expects, each in Chromium over real run files: the runs list (sortable,
with start, controller, engine, sampler, objective), damaged files listed, an empty run, importance with its
warning, the rungs of a multi-fidelity run, trials per worker over time, trial table filters, /redoc and /docs
without a request leaving the machine, a favicon."""

from __future__ import annotations

import json
import urllib.request

import numpy as np
import pytest

from spinefarm.storage.hdf5_reader import read_run
from tests.api_tests.test_dashboard_browser import ARTIFACTS
from tests.coordinator_tests.helpers import wait_for

pytestmark = pytest.mark.integration

RUNS = ["empty-run", "few-trials", "rungs-view", "spec-robot", "two-workers"]  # the run files of views_runs


@pytest.fixture(scope="module")
def runs(views_runs):
    return views_runs


@pytest.fixture(scope="module")
def server(views_server):
    return views_server


@pytest.fixture
def page(browser, server):
    ctx = browser.new_context(viewport={"width": 1400, "height": 900})
    pg = ctx.new_page()
    pg.requests, pg.errors = [], []
    pg.on("request", lambda r: pg.requests.append(r.url))  # every request, those a policy stops too
    pg.on("pageerror", lambda e: pg.errors.append(str(e)))
    pg.on("console", lambda m: m.type == "error" and pg.errors.append(m.text))
    yield pg
    assert not pg.errors, pg.errors
    assert not [u for u in pg.requests if not u.startswith((server.url, "blob:" + server.url))], pg.requests
    ctx.close()


def get(url: str):
    with urllib.request.urlopen(url, timeout=60) as r:
        return json.loads(r.read())


def column(page, key: str) -> list[str]:
    return page.eval_on_selector_all(f"#runs-table tbody tr td:nth-child({key})", "tds => tds.map(t => t.innerText)")


def test_runs_list_sortable_with_damaged_files_named(page, server):
    # on a busy machine a first read of a file can run out of time: the server tries it again
    wait_for(lambda: len(get(server.url + "/runs")) == len(RUNS), timeout_s=120, poll_s=1.0, what="every run file read")
    page.goto(server.url + "/")
    page.wait_for_selector(f"#runs-table tr.row >> nth={len(RUNS) - 1}")
    heads = page.eval_on_selector_all("#runs-table th", "ths => ths.map(t => t.innerText.replace(/[▲▼]/, '').trim())")
    for name in ("run", "robot", "state", "started", "controller", "engine", "sampler", "objective", "ETA"):
        assert name in heads
    col = {h: str(i + 1) for i, h in enumerate(heads)}
    started = [float(r["started_at_unix_s"]) for r in sorted(get(server.url + "/runs"), key=lambda r: r["run_id"])]
    assert column(page, col["run"]) == [n for _, n in sorted(zip(started, sorted(RUNS), strict=True),
                                                             reverse=True)]  # newest first
    for order in (sorted(RUNS), sorted(RUNS, reverse=True)):
        page.click("#runs-table th[data-key=run_id]")
        mark = "sorted-asc" if order[0] == "empty-run" else "sorted-desc"
        wait_for(lambda mark=mark: page.locator("#runs-table th[data-key=run_id]").get_attribute("class").endswith(
            mark), timeout_s=10, poll_s=0.1, what="the table sorted by run")
        assert column(page, col["run"]) == order
    by_run = dict(zip(column(page, col["run"]), column(page, col["sampler"]), strict=True))
    assert by_run["rungs-view"] == "random" and by_run["two-workers"] == "cmaes"
    states = dict(zip(column(page, col["run"]), column(page, col["state"]), strict=True))
    assert states == {"two-workers": "done", "rungs-view": "done", "few-trials": "done", "empty-run": "empty",
                      "spec-robot": "done"}
    assert "speed" in column(page, col["objective"])
    damaged = page.locator("#damaged").inner_text()
    assert "broken.h5" in damaged and "1 file left out" in damaged
    page.screenshot(path=ARTIFACTS / "runs-list.png", full_page=True)


def test_an_empty_run_says_so(page, server):
    page.goto(server.url + "/#/run/empty-run")
    page.wait_for_selector("#empty:not([hidden])")
    assert "No finished trial yet" in page.locator("#empty").inner_text()
    assert page.locator("#run-body").is_hidden()
    assert page.locator(".js-plotly-plot").count() == 0  # no empty axes, no bar labels
    assert "spinefarm search --resume" in page.locator("#empty").inner_text()
    page.screenshot(path=ARTIFACTS / "run-empty.png", full_page=True)


def test_importance_warns_below_a_trial_count(page, server):
    page.goto(server.url + "/#/run/few-trials")
    page.wait_for_selector("#trial-table tr.row")
    warning = page.locator("#importance-warning")
    wait_for(lambda: warning.is_visible(), timeout_s=20, poll_s=0.1, what="the importance warning")
    assert "from 8 finished trials of 40 parameters" in " ".join(warning.inner_text().split())
    page.goto(server.url + "/#/run/two-workers")  # 60 trials of 9 parameters: enough
    page.wait_for_selector("#trial-table tr.row")
    wait_for(lambda: page.locator("#plot-importance .bars path").count() == 9, timeout_s=20, poll_s=0.1,
             what="the importance plot")
    assert page.locator("#importance-warning").is_hidden()


def test_rungs_view_and_filters_on_a_multi_fidelity_run(page, server, runs):
    _, cols = read_run(runs / "rungs.h5")
    promoted = int(((cols["rung"] == 1) & (cols["parent"] >= 0)).sum())
    assert promoted >= 1
    page.goto(server.url + "/#/run/rungs-view")
    page.wait_for_selector("#trial-table tr.row")
    wait_for(lambda: page.locator("#plot-rungs").get_attribute("data-promotions") is not None, timeout_s=20,
             poll_s=0.1, what="the rungs plot")
    assert page.locator("#rungs-panel").is_visible()
    assert int(page.locator("#plot-rungs").get_attribute("data-promotions")) == promoted
    rows = page.locator("#rungs-table tbody tr")
    assert rows.count() == 2
    cells = rows.nth(0).locator("td").all_inner_texts()
    assert cells[:5] == ["0", "0.05", str(int((cols["rung"] == 0).sum())), str(int(
        ((cols["rung"] == 0) & (cols["status"] == b"complete")).sum())), str(promoted)]
    # filters: the promoted rows only, then those with an objective of at least the median
    page.select_option("#trial-filters select[data-filter=phase]", "promoted")
    n_promoted = int((cols["phase"] == b"promoted").sum())
    assert page.locator("#trial-table tr.row").count() == n_promoted
    assert page.locator("#filter-count").inner_text() == f"{n_promoted} of {len(cols['trial_id'])} trials"
    threshold = float(np.median(cols["objective"][cols["phase"] == b"promoted"]))
    page.fill("#trial-filters input[data-filter=min_objective]", repr(threshold))
    expected = int(((cols["phase"] == b"promoted") & (cols["objective"] >= threshold)).sum())
    assert page.locator("#trial-table tr.row").count() == expected
    page.screenshot(path=ARTIFACTS / "run-rungs.png", full_page=True)


def test_trials_per_worker_over_time(page, server, runs):
    _, cols = read_run(runs / "two.h5")
    workers = {w for w in cols["worker_id"].tolist() if w}
    assert len(workers) == 2
    page.goto(server.url + "/#/run/two-workers")
    page.wait_for_selector("#trial-table tr.row")
    timeline = page.locator("#plot-timeline")
    wait_for(lambda: timeline.get_attribute("data-workers") == "2", timeout_s=20, poll_s=0.1, what="the timeline")
    assert timeline.get_attribute("data-points") == str(int(np.isfinite(cols["finished_at_unix_s"]).sum()))
    assert page.locator("#plot-timeline .scatterlayer .trace").count() == 2
    assert page.locator("#plot-rungs-panel, #rungs-panel").first.is_hidden()  # not a multi-fidelity run


def test_redoc_docs_and_favicon_stay_on_this_machine(page, server):
    for path, ready in (("/redoc", "[data-section-id]"), ("/docs", ".swagger-ui .opblock"), ("/", "#runs-table")):
        page.goto(server.url + path)
        page.wait_for_selector(ready, timeout=30_000)
        page.wait_for_timeout(1500)  # late requests (Redoc's footer logo) happen after the first paint
    with urllib.request.urlopen(server.url + "/favicon.ico", timeout=10) as r:
        assert r.status == 200 and r.headers["content-type"].startswith("image/svg+xml")
    # the page fixture asserts that no request left this server


def test_workers_left_out_and_a_raised_fidelity_are_shown(browser, tmp_path):
    """What the coordinator's status says went on beside the trials (tests/coordinator_tests/test_core.py makes
    both happen): the run page names each worker left out with why, and why the judge raised the fidelity."""
    from spinefarm.storage.status import read_status, write_status
    from tests.api_tests.test_dashboard_browser import Server, free_port, spinefarm

    out = tmp_path / "left.h5"
    spinefarm("search", "sphere:3", "--trials", "6", "--workers", "1", "--out", str(out), "--run-id", "left-out",
              "--api-port", "-1", "--quiet")
    status = read_status(out)
    assert status["unservable_workers"] == {} and status["fidelity_raised"] is None  # a search where neither happened
    left = {"old-box": "engine 'mujoco' is not installed", "w<7>": "space hash differs: an older install"}
    write_status(out, {**status, "unservable_workers": left, "fidelity_raised": "median ratio 1.3 of 3 judged bests"})
    port = free_port()
    server = Server(["api", str(out), "--port", str(port)], port)
    try:
        assert get(server.url + "/runs/left-out")["unservable_workers"] == left
        pg = browser.new_page()
        errors: list[str] = []
        pg.on("pageerror", lambda e: errors.append(str(e)))
        pg.goto(server.url + "/#/run/left-out")
        pg.wait_for_selector("#cards .card")
        assert not errors, errors
        notice = pg.wait_for_selector("#unservable-workers")
        assert notice.inner_text().startswith("2 workers left out of this run")
        assert [li.inner_text() for li in notice.query_selector_all("li")] == [
            "old-box: engine 'mujoco' is not installed", "w<7>: space hash differs: an older install"]
        assert "median ratio 1.3 of 3 judged bests" in pg.inner_text("#fidelity-raised")
        pg.screenshot(path=str(ARTIFACTS / "views-unservable-workers.png"), full_page=True)
        pg.close()
    finally:
        server.stop()


def test_a_status_file_set_aside_is_said_on_the_run_page(browser, tmp_path):
    """A malformed status file (a worker entry of another shape) is set aside by the API; the run page says so."""
    from spinefarm.storage.status import read_status, write_status
    from tests.api_tests.test_dashboard_browser import Server, free_port, spinefarm

    out = tmp_path / "odd.h5"
    spinefarm("search", "sphere:3", "--trials", "6", "--workers", "1", "--out", str(out), "--run-id", "odd-status",
              "--api-port", "-1", "--quiet")
    write_status(out, {**read_status(out), "workers": [{"worker_id": 7}]})
    port = free_port()
    server = Server(["api", str(out), "--port", str(port)], port)
    try:
        pg = browser.new_page()
        errors: list[str] = []
        pg.on("pageerror", lambda e: errors.append(str(e)))
        pg.goto(server.url + "/#/run/odd-status")
        pg.wait_for_selector("#cards .card")
        assert not errors, errors
        text = pg.wait_for_selector("#status-file-error").inner_text()
        assert "is malformed and left out: workers.0" in text and "from the run file alone" in text
        pg.close()
    finally:
        server.stop()
