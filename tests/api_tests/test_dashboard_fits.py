"""The dashboard on a 1280 x 800 screen (Chromium through Playwright): the runs list, a run page, the compare view
and a trial page fit it without horizontal overflow, and a trial's gait moves within 2 s of opening (unless the
reader's system asks for reduced motion)."""

from __future__ import annotations

import pytest

from tests.api_tests.test_dashboard_browser import ARTIFACTS, Server, free_port, spinefarm
from tests.coordinator_tests.helpers import wait_for

pytestmark = pytest.mark.integration

SCREEN = {"width": 1280, "height": 800}
# run ids as long as `search` makes them (robot name, date, time, random)
RUNS = ("tetraspine-ntrt-20261206-031500-a1b2", "tetraspine-ntrt-20261206-031700-c3d4")
LOAD_MS = 240_000

# every element whose box ends right of the page, and every scrolling box whose content is wider than itself
OVERFLOW = """() => { const width = document.documentElement.clientWidth; const out = [];
  const name = (el) => el.tagName.toLowerCase() + (el.id ? '#' + el.id : '') + (el.className && el.className.baseVal
    === undefined ? '.' + String(el.className).trim().split(/\\s+/).join('.') : '');
  for (const el of document.querySelectorAll('body *')) {
    const r = el.getBoundingClientRect();
    if (r.width > 0 && r.right > width + 1) out.push(`${name(el)} ends at ${Math.round(r.right)} px`);
    const x = getComputedStyle(el).overflowX;
    if ((x === 'auto' || x === 'scroll') && el.scrollWidth > el.clientWidth + 1)
      out.push(`${name(el)} scrolls sideways: ${el.scrollWidth} px in ${el.clientWidth} px`);
  }
  if (document.documentElement.scrollWidth > width) out.push(`the page is ${document.documentElement.scrollWidth} px`);
  return out; }"""


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    d = tmp_path_factory.mktemp("fits")
    for seed, run_id in enumerate(RUNS):
        spinefarm("search", "tetraspine-ntrt", "--trials", "3", "--workers", "1", "--engine", "bullet", "--duration",
                  "1", "--out", str(d / f"{run_id}.h5"), "--run-id", run_id, "--api-port", "-1", "--quiet",
                  "--seed", str(seed), "--no-verify")
    port = free_port()
    s = Server(["api", *(str(d / f"{r}.h5") for r in RUNS), "--port", str(port)], port)
    yield s
    s.stop()


def open_page(browser, url: str, ready: str, **context):
    ctx = browser.new_context(viewport=SCREEN, **context)
    page = ctx.new_page()
    page.goto(url)
    page.wait_for_selector(ready, timeout=LOAD_MS)
    return ctx, page


@pytest.mark.parametrize(("name", "path", "ready"), [
    ("runs-list", "#/", "#runs-table tr.row"),
    ("run-page", f"#/run/{RUNS[0]}", "#trial-table tr"),
    ("compare", f"#/compare/{RUNS[0]},{RUNS[1]}", "#compare-table tr"),
    ("trial-page", f"#/run/{RUNS[0]}/trial/1", "#motion-area[data-ready]"),
])
def test_each_page_fits_a_1280_px_screen(browser, server, name, path, ready):
    ctx, page = open_page(browser, f"{server.url}/{path}", ready)
    try:
        if name == "run-page":
            page.click("#pc-controls summary")  # the list of axes, opened
        page.wait_for_timeout(500)  # plots and tables laid out
        page.screenshot(path=ARTIFACTS / f"fits-1280-{name}.png", full_page=True)
        assert page.evaluate(OVERFLOW) == []
    finally:
        ctx.close()


def test_the_gait_plays_when_opened_and_stays_still_for_reduced_motion(browser, server):
    url = f"{server.url}/#/run/{RUNS[0]}/trial/1"
    ctx, page = open_page(browser, url, "#motion-area[data-ready]")
    try:
        first = page.evaluate("() => [document.getElementById('motion-0').motionView.frame, "
                              "Number(document.getElementById('motion-bar').dataset.time)]")
        wait_for(lambda: page.evaluate("() => [document.getElementById('motion-0').motionView.frame, Number("
                                       "document.getElementById('motion-bar').dataset.time)]") != first,
                 timeout_s=2.0, poll_s=0.05, what="the gait to move within 2 s of opening")
        assert page.locator("#motion-bar").get_attribute("data-playing") == "1"
    finally:
        ctx.close()
    ctx, page = open_page(browser, url, "#motion-area[data-ready]", reduced_motion="reduce")
    try:
        page.wait_for_timeout(1000)
        assert page.locator("#motion-bar").get_attribute("data-playing") != "1"
        assert page.locator("#motion-bar").get_attribute("data-time") == "0"
    finally:
        ctx.close()


def test_the_run_page_draws_the_objectives_edf_and_a_rank_plot(browser, server):
    import json
    import urllib.request

    with urllib.request.urlopen(f"{server.url}/runs/{RUNS[0]}/columns", timeout=60) as r:
        cols = json.load(r)
    c = cols["columns"]
    ok = [i for i in range(cols["n_trials"]) if c["status"][i] == "complete" and c["objective"][i] is not None]
    objective = [c["objective"][i] for i in ok]
    assert len(ok) == 3 and len(set(objective)) == 3  # distinct values: every rank shows
    ctx, page = open_page(browser, f"{server.url}/#/run/{RUNS[0]}", "#plot-rank .main-svg")
    try:
        edf = page.evaluate("() => { const d = document.getElementById('plot-edf').data[0]; return [d.x, d.y]; }")
        assert edf == [sorted(objective), [1 / 3, 2 / 3, 1.0]]  # the share of trials at most each value
        rank = page.evaluate("""() => { const d = document.getElementById('plot-rank').data[0];
            return {ids: d.customdata, colour: d.marker.color}; }""")
        # colour: 0 for the lowest objective, 0.5 the middle, 1 the highest (the best: objectives are maximised)
        expected = {c["trial_id"][i]: sorted(objective).index(c["objective"][i]) / 2 for i in ok}
        assert dict(zip(rank["ids"], rank["colour"], strict=True)) == expected
        names = cols["param_names"]
        assert page.locator("#rank-x").input_value() in names and page.locator("#rank-y").input_value() in names
        page.select_option("#rank-y", "objective")
        ys = page.evaluate("() => document.getElementById('plot-rank').data[0].y")
        assert sorted(ys) == sorted(objective)
    finally:
        ctx.close()


def test_the_compare_view_draws_each_runs_edf(browser, server):
    import json
    import urllib.request

    want = []
    for run_id in RUNS:
        with urllib.request.urlopen(f"{server.url}/runs/{run_id}/columns?params=false", timeout=60) as r:
            c = json.load(r)["columns"]
        want.append(sorted(v for s, v in zip(c["status"], c["objective"], strict=True) if s == "complete"))
    ctx, page = open_page(browser, f"{server.url}/#/compare/{RUNS[0]},{RUNS[1]}", "#compare-edf .main-svg")
    try:
        drawn = page.evaluate("() => document.getElementById('compare-edf').data.map((d) => [d.x, d.y])")
        assert drawn == [[xs, [(k + 1) / len(xs) for k in range(len(xs))]] for xs in want]
    finally:
        ctx.close()

