"""Exploring runs in Chromium over real run files: parallel coordinates with brushes, the objective over two
parameters (and its endpoint), runs compared side by side, parameter columns in the trials table."""

from __future__ import annotations

import json
import urllib.error
import urllib.request

import numpy as np
import pytest

from spinefarm.storage.hdf5_reader import read_run
from tests.api_tests.conftest import SPEC_ROBOT
from tests.api_tests.test_dashboard_browser import ARTIFACTS
from tests.coordinator_tests.helpers import wait_for

pytestmark = pytest.mark.integration

OBJ_AXIS = "__objective"


@pytest.fixture
def page(browser, views_server):
    ctx = browser.new_context(viewport={"width": 1400, "height": 900})
    pg = ctx.new_page()
    pg.requests, pg.errors = [], []
    pg.on("request", lambda r: pg.requests.append(r.url))
    pg.on("pageerror", lambda e: pg.errors.append(str(e)))
    pg.on("console", lambda m: m.type == "error" and pg.errors.append(m.text))
    yield pg
    assert not pg.errors, pg.errors
    local = (views_server.url, "blob:" + views_server.url, "data:")
    assert not [u for u in pg.requests if not u.startswith(local)], pg.requests
    ctx.close()


def get(url: str):
    with urllib.request.urlopen(url, timeout=60) as r:
        return json.loads(r.read())


def error_of(url: str) -> tuple[int, str]:
    with pytest.raises(urllib.error.HTTPError) as e:
        urllib.request.urlopen(url, timeout=60)
    return e.value.code, json.loads(e.value.read())["detail"]["message"]


def counted(cols) -> np.ndarray:
    """Rows every view draws: complete, a finite objective, not refuted at a finer step."""
    refuted = cols["verification"] == b"not_reproduced"
    return (cols["status"] == b"complete") & np.isfinite(cols["objective"]) & ~refuted


def open_run(page, url: str, run_id: str) -> None:
    page.goto(f"{url}/#/run/{run_id}")
    page.wait_for_selector("#trial-table tr.row")
    page.wait_for_selector("#pc-svg .pc-axis")
    page.wait_for_selector("#contour-svg, #contour-empty")


def drag(page, axis: str, from_frac: float, to_frac: float) -> tuple[float, float]:
    """Brush an axis from one height to another (0 top, 1 bottom); the range it selected, in data units."""
    hit = page.locator(f'#pc-svg .pc-axis[data-key="{axis}"] .pc-hit')
    hit.scroll_into_view_if_needed()
    b = hit.bounding_box()
    x, top, span = b["x"] + b["width"] / 2, b["y"] + 4, b["height"] - 8  # the hit area reaches 4 px past the axis
    page.mouse.move(x, top + from_frac * span)
    page.mouse.down()
    page.mouse.move(x, top + to_frac * span, steps=4)
    page.mouse.up()
    g = page.locator(f'#pc-svg .pc-axis[data-key="{axis}"]')
    return float(g.get_attribute("data-lo")), float(g.get_attribute("data-hi"))


def labels_inside(page) -> list[str]:
    """Axis labels of the parallel coordinates that reach outside their panel (clipped)."""
    return page.evaluate("""() => { const box = document.getElementById('pc-box').getBoundingClientRect();
        return [...document.querySelectorAll('#pc-svg .pc-label')].filter((t) => { const r = t.getBoundingClientRect();
          return r.left < box.left - 0.5 || r.right > box.right + 0.5 || r.bottom > box.bottom + 0.5; })
          .map((t) => t.textContent); }""")


def test_a_brush_lists_the_trials_inside_it(page, views_server, views_runs):
    meta, cols = read_run(views_runs / "two.h5")
    ok = counted(cols)
    analysis = get(views_server.url + "/runs/two-workers/analysis")
    open_run(page, views_server.url, "two-workers")
    imp = [analysis["importance"][n] for n in meta.param_names]
    default = sorted(sorted(range(len(imp)), key=lambda j: (-imp[j], j))[:8])
    axes = page.eval_on_selector_all("#pc-svg .pc-axis", "gs => gs.map(g => g.dataset.key)")
    assert axes == [meta.param_names[j] for j in default] + [OBJ_AXIS]  # the 8 most important, and the objective
    assert labels_inside(page) == []
    box = page.locator("#pc-box")
    assert box.get_attribute("data-lines") == box.get_attribute("data-brushed") == str(int(ok.sum()))
    name = meta.param_names[default[0]]
    lo, hi = drag(page, name, 0.1, 0.7)
    x = cols["params"][:, default[0]]
    inside = ok & (x >= lo) & (x <= hi)
    assert 0 < inside.sum() < ok.sum()
    assert box.get_attribute("data-brushed") == str(int(inside.sum()))
    olo, ohi = drag(page, OBJ_AXIS, 0.0, 0.6)  # a second brush: both ranges hold
    inside &= (cols["objective"] >= olo) & (cols["objective"] <= ohi)
    assert page.locator("#pc-count").inner_text() == f"{int(inside.sum())} of {int(ok.sum())} trials inside the brushes"
    page.check("#pc-only")
    shown = page.eval_on_selector_all("#trial-table tr.row", "rows => rows.map(r => Number(r.dataset.trial))")
    assert sorted(shown) == cols["trial_id"][inside].tolist()
    links = page.eval_on_selector_all("#pc-ids a", "as => as.map(a => Number(a.textContent))")
    assert set(links) <= set(shown) and len(links) == min(40, len(shown))
    page.screenshot(path=ARTIFACTS / "run-parallel-brushed.png", full_page=True)
    page.click(f'#pc-svg .pc-axis[data-key="{OBJ_AXIS}"] .pc-hit')  # a click clears that axis' brush
    wait_for(lambda: box.get_attribute("data-brushed") == str(int((ok & (x >= lo) & (x <= hi)).sum())),
             timeout_s=5, poll_s=0.05, what="the objective's brush cleared")
    # another axis from the list: it is drawn, in the parameters' order
    other = next(j for j in range(len(meta.param_names)) if j not in default)
    page.click("#pc-axes summary")
    page.check(f'#pc-axes input[value="{meta.param_names[other]}"]')
    axes = page.eval_on_selector_all("#pc-svg .pc-axis", "gs => gs.map(g => g.dataset.key)")
    assert axes == [meta.param_names[j] for j in sorted([*default, other])] + [OBJ_AXIS]


def test_the_contour_endpoint_follows_the_run_file(views_server, views_runs):
    meta, cols = read_run(views_runs / "two.h5")
    jx, jy = 2, 5
    x, y = meta.param_names[jx], meta.param_names[jy]
    g = get(f"{views_server.url}/runs/two-workers/contour?x={x}&y={y}&grid=7")
    ok = counted(cols)
    assert g["points"]["trial_id"] == cols["trial_id"][ok].tolist()
    assert len(g["z"]) == 7 and all(len(row) == 7 for row in g["z"])
    # every cell: the Gaussian-weighted mean of the trials' objectives, positions as fractions of each range
    lo, hi = np.array(meta.param_lows), np.array(meta.param_highs)
    u = (cols["params"][ok][:, [jx, jy]] - lo[[jx, jy]]) / (hi - lo)[[jx, jy]]
    centres = (np.arange(7) + 0.5) / 7
    h = g["bandwidth"]
    assert 0 < h <= 0.25
    for i in range(7):
        for j in range(7):
            w = np.exp(-0.5 * ((u[:, 0] - centres[j]) ** 2 + (u[:, 1] - centres[i]) ** 2) / h**2)
            assert g["z"][i][j] == pytest.approx(float(w @ cols["objective"][ok] / w.sum()), rel=1e-9)
    assert g["x_centres"] == pytest.approx((lo[jx] + centres * (hi[jx] - lo[jx])).tolist())
    assert g["value_name"] == meta.objective
    empty = get(f"{views_server.url}/runs/empty-run/contour?x=x0&y=x1&grid=3")
    assert empty["points"]["trial_id"] == [] and empty["z"] == [[None] * 3] * 3
    base = f"{views_server.url}/runs/two-workers/contour"
    first = meta.param_names[0]
    for query, words in ((f"x=nope&y={y}", ["x: no such parameter", "received 'nope'", f"one of {first}"]),
                         (f"x={x}&y={x}", ["the same parameter", f"received '{x}'"]),
                         (f"x={x}&y={y}&grid=1", ["grid out of range", "received 1", "[2, 200]"]),
                         (f"x={x}&y={y}&grid=500", ["received 500"]),
                         (f"x={x}&y={y}&grid=ten", ["grid", "received 'ten'"]),
                         (f"x={x}&y={y}&value=work_j", ["received 'work_j'", "one of objective"])):
        status, message = error_of(f"{base}?{query}")
        assert status == 422 and "\n" not in message
        assert all(w in message for w in words), (query, message)


def test_the_contour_view_draws_the_chosen_pair(page, views_server, views_runs):
    meta, cols = read_run(views_runs / "two.h5")
    open_run(page, views_server.url, "two-workers")
    box = page.locator("#contour-box")
    assert box.get_attribute("data-points") == str(int(counted(cols).sum()))
    assert page.locator("#contour-svg .contour-dots circle").count() == int(counted(cols).sum())
    assert int(box.get_attribute("data-cells")) > 0
    x, y = meta.param_names[4], meta.param_names[7]
    page.select_option("#contour-x", x)
    page.select_option("#contour-y", y)
    wait_for(lambda: (box.get_attribute("data-drawn") or "").startswith(f"{x}|{y}|"),
             timeout_s=10, poll_s=0.05, what="the new pair drawn")
    texts = page.locator("#contour-svg").text_content()
    assert x in texts and y in texts
    page.locator("#contour-panel").screenshot(path=ARTIFACTS / "run-contour.png")


@pytest.mark.parametrize("run_id, file", [("rungs-view", "rungs.h5"), ("spec-robot", "spec.h5")])
def test_the_new_views_on_a_multi_fidelity_run_and_a_robot_from_a_spec_file(page, views_server, views_runs, run_id,
                                                                             file):
    meta, cols = read_run(views_runs / file)
    open_run(page, views_server.url, run_id)
    n = int((counted(cols) & (cols["rung"] == 0)).sum())  # a multi-fidelity run's first rung (one rung: all)
    assert n > 0
    assert page.locator("#pc-box").get_attribute("data-lines") == str(n)
    assert page.locator("#pc-svg .pc-axis").count() == min(8, meta.n_params) + 1
    assert labels_inside(page) == []  # the robot's long parameter names too
    assert page.locator("#contour-box").get_attribute("data-points") == str(n)
    page.screenshot(path=ARTIFACTS / f"run-explore-{run_id}.png", full_page=True)


def test_comparing_runs_of_two_robots(page, views_server):
    page.goto(views_server.url + "/")
    page.wait_for_selector("#runs-table tr.row")
    assert page.locator("#compare-runs").is_disabled()
    for run_id in ("two-workers", "spec-robot"):
        page.check(f'#runs-table input.pick[value="{run_id}"]')
    assert page.locator("#compare-runs").inner_text() == "compare the picked runs (2)"
    page.click("#compare-runs")
    page.wait_for_selector("#compare-table tbody tr >> nth=1")
    assert page.url.endswith("#/compare/two-workers,spec-robot")
    for run_id, robot in (("two-workers", "sphere:9"), ("spec-robot", SPEC_ROBOT)):
        status = get(f"{views_server.url}/runs/{run_id}")
        row = page.locator(f'#compare-table tr[data-run="{run_id}"]')
        assert row.locator("td").nth(1).inner_text() == robot
        shown = float(row.locator('td[data-best="objective"]').inner_text())
        assert shown == pytest.approx(status["best"]["objective"], rel=1e-3)
        # a judged best shows the judge's speed (docs/distributed.md), an unjudged one the screen's
        judged = (status["best"].get("verification") or {}).get("judged_speed_cm_s")
        speed = judged if judged is not None else status["best"]["scores"]["speed_cm_s"]
        assert float(row.locator('td[data-best="speed_cm_s"]').inner_text()) == pytest.approx(speed, rel=1e-3)
    wait_for(lambda: page.locator("#compare-time .scatterlayer .trace").count() == 2, timeout_s=10, poll_s=0.05,
             what="the curves against time")
    assert page.locator("#compare-trials .scatterlayer .trace").count() == 2
    assert "two-workers (sphere:9)" in page.locator("#compare-trials .legend").text_content()
    page.screenshot(path=ARTIFACTS / "compare-runs.png", full_page=True)
    page.goto(views_server.url + "/#/compare/two-workers,few-trials")  # distance against speed: a shared score
    page.wait_for_selector("#mixed-objectives")
    assert page.locator("#compare-metric").input_value() == "distance_m"


def test_a_parameter_column_in_the_trials_table(page, views_server, views_runs):
    meta, cols = read_run(views_runs / "spec.h5")
    open_run(page, views_server.url, "spec-robot")
    j = meta.n_params - 1
    name = meta.param_names[j]
    page.select_option("#add-param-col", name)
    head = page.locator(f'#trial-table th[data-key="param:{name}"]')
    assert name in head.inner_text()
    k = page.eval_on_selector_all("#trial-table th", "ths => ths.map(t => t.dataset.key)").index(f"param:{name}")

    def shown() -> list[tuple[int, float]]:
        return page.eval_on_selector_all(
            "#trial-table tr.row", f"rows => rows.map(r => [Number(r.dataset.trial), Number(r.cells[{k}].innerText)])")

    values = shown()
    assert len(values) == len(cols["trial_id"])
    for trial, v in values:
        assert v == pytest.approx(cols["params"][trial, j], rel=1e-3, abs=1e-9)
    head.click()  # sorted, largest first
    assert [v for _, v in shown()] == sorted((v for _, v in values), reverse=True)
    threshold = float(np.median(cols["objective"]))
    page.fill("#trial-filters input[data-filter=min_objective]", repr(threshold))  # the column stays when filtering
    assert [t for t, _ in shown()] == sorted((int(t) for t in cols["trial_id"][cols["objective"] >= threshold]),
                                             key=lambda t: -cols["params"][t, j])
    page.locator(f'#trial-table th[data-key="param:{name}"] .drop').click()
    assert page.locator(f'#trial-table th[data-key="param:{name}"]').count() == 0


def test_parameter_views_of_a_multi_fidelity_run_take_its_first_rung(page, views_server, views_runs):
    meta, cols = read_run(views_runs / "rungs.h5")
    ok = counted(cols)
    first, second = ok & (cols["rung"] == 0), ok & (cols["rung"] == 1)
    assert first.sum() and second.sum()  # both rungs finished trials: mixing them would show
    x, y = meta.param_names[0], meta.param_names[1]
    base = f"{views_server.url}/runs/rungs-view/contour?x={x}&y={y}&grid=5"
    g = get(base)
    assert g["rung"] == 0 and g["rungs"] == 2
    assert g["points"]["trial_id"] == cols["trial_id"][first].tolist()
    assert get(base + "&rung=1")["points"]["trial_id"] == cols["trial_id"][second].tolist()
    for bad, words in (("2", ["rung out of range", "received 2", "[0, 1]"]), ("-1", ["received -1"]),
                       ("one", ["rung", "received 'one'"])):
        status, message = error_of(f"{base}&rung={bad}")
        assert status == 422 and all(w in message for w in words), message
    # importance ranks each parameter set once: from the first rung's finished trials
    assert get(f"{views_server.url}/runs/rungs-view/analysis")["importance_trials"] == int(first.sum())
    # the page: parallel coordinates draw one line per first-rung trial and say why
    open_run(page, views_server.url, "rungs-view")
    wait_for(lambda: page.locator("#pc-box").get_attribute("data-lines") == str(int(first.sum())), timeout_s=10,
             poll_s=0.05, what="one line per first-rung trial")
    note = page.locator("#params-rung-note")
    assert note.is_visible() and "first rung only (0.05 s trials)" in note.inner_text()
    open_run(page, views_server.url, "two-workers")  # one rung: every finished trial, no note
    every = str(int(counted(read_run(views_runs / "two.h5")[1]).sum()))
    wait_for(lambda: page.locator("#pc-box").get_attribute("data-lines") == every, timeout_s=10, poll_s=0.05,
             what="one line per finished trial")
    assert page.locator("#params-rung-note").is_hidden()
