"""A judged best's cost of transport is the judge's: every evaluation row keeps the COT its run measured, and
the final report, `/runs/ID`, `/runs/ID/best`, `/runs/ID/trials/ID` and the dashboard show the judge's COT beside
its distance (the screen's apart), and the dashboard the judged speed. A run file of schema 8
(tests/storage_tests/data/run-schema8.h5, written by spinefarm at ce6864d: four trials with screen COTs 1, 2, 3
and 4; trials 1 and 3 judged in Bullet, an opinion and an audit on trial 1) has no such column: it opens
everywhere and says "not measured".

The rows here are written through the storage API as the coordinator stores them; the real search whose judged
COT is held against an independent `spinefarm trial` is tests/coordinator_tests/test_judged_cot_search.py."""

from __future__ import annotations

import math
import shutil

import h5py
import numpy as np
import pytest

from spinefarm.api.app import create_app
from spinefarm.cli.report import final_report
from spinefarm.storage.evaluations import NOT_MEASURED, row_of
from spinefarm.storage.hdf5 import Hdf5Storage
from spinefarm.storage.schema import FILE_SCHEMA_VERSION
from tests.api_tests.judged import OLD, result_with_cot, write_cot_run
from tests.http_server import served

# run-c (tests.api_tests.judged): trials 0-3 screened at 0.05, 0.30, 0.02, 0.21 m with COTs 1.1, 2.2, 3.3, 4.4;
# Bullet at 0.25 ms judges trial 1 (0.40 m, COT 5.5) and trial 3 (0.25 m, 6.6); MuJoCo at 1 ms gives its opinion
# on trial 1 (0.32 m, 7.7), another worker audits it (0.30 m, 8.8)


def test_every_evaluation_row_keeps_its_cot_with_its_unit(tmp_path):
    write_cot_run(tmp_path / "c.h5")
    with Hdf5Storage.open_read(tmp_path / "c.h5") as s:
        ev = s.evaluations()
    got = {(int(t), k.decode()): float(c) for t, k, c in zip(ev["trial_id"], ev["kind"], ev["cot"], strict=True)}
    assert got == {(1, "judge"): 5.5, (3, "judge"): 6.6, (1, "opinion"): 7.7, (1, "audit"): 8.8}
    with h5py.File(tmp_path / "c.h5", "r") as f:
        assert f["evaluations/cot"].attrs["unit"] == "1" and f.attrs["file_schema_version"] == FILE_SCHEMA_VERSION


def test_best_the_trial_page_and_the_run_show_the_judges_cot_not_the_screens(tmp_path):
    write_cot_run(tmp_path / "c.h5")
    with served(create_app(runs_dir=tmp_path)) as c:
        best = c.get("/runs/run-c/best", params={"k": 3}).json()
        page = c.get("/runs/run-c/trials/3").json()
        unjudged = c.get("/runs/run-c/trials/0").json()
        run = c.get("/runs/run-c").json()
    assert [b["trial_id"] for b in best] == [1, 3, 0]   # judged 0.40 and 0.25 m, then the screen's 0.05 m
    assert [b["judged_cot"] for b in best] == [5.5, 6.6, None]
    assert [b["scores"]["cot"] for b in best] == [2.2, 4.4, 1.1]     # the screen's stay where they were
    assert best[0]["judged_cot_note"] is None and best[2]["judged_cot_note"] is None   # not judged: nothing to say
    assert (page["judged_cot"], unjudged["judged_cot"]) == (6.6, None)
    assert run["best"]["trial_id"] == 1 and run["best"]["judged_cot"] == 5.5
    assert best[0]["model_spread"]["judge"]["cot"] == 5.5 and best[0]["model_spread"]["other"]["cot"] == 7.7
    # the ratio the judge stores is the screen's distance over the judge's (coordinator/ladder/checks.py), by
    # hand from the rows above: trial 1 0.30 / 0.40 m, trial 3 0.21 / 0.25 m; none for a trial not judged
    assert best[0]["verification"]["screen_to_judge_ratio"] == pytest.approx(0.75, rel=1e-12)
    assert page["verification"]["screen_to_judge_ratio"] == pytest.approx(0.84, rel=1e-12)
    assert unjudged["verification"]["screen_to_judge_ratio"] is None


def test_the_final_report_gives_the_judges_cot_beside_its_distance(tmp_path):
    write_cot_run(tmp_path / "c.h5")
    with Hdf5Storage.open_read(tmp_path / "c.h5") as s:
        text = final_report(s, tmp_path / "c.h5", verdict="", done=True)
    [line] = [x for x in text.splitlines() if "distance 0.4 m (judged)" in x]
    speed_cm_s = 100 * 0.40 / 5.0   # the judged distance over result()'s simulated 5 s
    assert line.strip() == (f"distance 0.4 m (judged) · speed {speed_cm_s:.4g} cm/s (judged) · COT 5.5 (judged) · "
                            "screen's COT 2.2, work 3 J")


def test_a_schema_8_file_opens_everywhere_says_not_measured_and_resumes_at_the_current_schema(tmp_path):
    path = tmp_path / "old.h5"
    shutil.copy(OLD, path)
    with h5py.File(path, "r") as f:
        assert f.attrs["file_schema_version"] == 8 and "cot" not in f["evaluations"]
    with Hdf5Storage.open_read(path) as s:
        ev = s.evaluations()
        assert ev["kind"].tolist() == [b"judge", b"judge", b"opinion", b"audit"] and np.isnan(ev["cot"]).all()
        text = final_report(s, path, verdict="", done=True)
    assert f"COT {NOT_MEASURED} · screen's COT 2" in text
    with served(create_app(runs_dir=tmp_path)) as c:
        st = c.get("/runs/run-v8").json()
        best = c.get("/runs/run-v8/best", params={"k": 1}).json()[0]
    assert st["file_schema_version"] == 8 and "not measured" in st["file_note"]
    assert best["trial_id"] == 1 and best["judged_cot"] is None and best["judged_cot_note"] == NOT_MEASURED
    assert best["model_spread"]["other"]["cot"] is None and best["model_spread"]["other"]["distance_m"] == 0.32
    resumed = Hdf5Storage.resume(path)   # rewritten at the current schema; the rows keep their NaN COT
    try:
        resumed.add_evaluation(row_of(3, "opinion", result_with_cot(3, 0.2, 9.9), "mujoco", 1e-3, "w-opinion"))
    finally:
        resumed.close()
    with h5py.File(path, "r") as f:
        assert f.attrs["file_schema_version"] == FILE_SCHEMA_VERSION
        cot = f["evaluations/cot"][:]
    assert np.isnan(cot[:4]).all() and cot[4] == 9.9 and not math.isnan(cot[4])


@pytest.mark.integration
def test_the_dashboard_and_the_trial_page_show_the_judges_cot(browser, judged_server):
    page = browser.new_page()
    shown = {}
    for run, trial in (("run-c", 3), ("run-v8", 1)):
        page.goto(f"{judged_server.url}/#/run/{run}")
        page.wait_for_selector("#best-cot")
        shown[run] = page.locator("#best-cot").inner_text()
        shown[run, "speed"] = page.locator("#best-speed").inner_text()
        page.goto(f"{judged_server.url}/#/")
        page.wait_for_selector(f"tr[data-run='{run}']")
        heads = page.locator("thead th").all_inner_texts()
        cells = page.locator(f"tr[data-run='{run}'] td").all_inner_texts()
        shown[run, "listed"] = cells[heads.index("best COT")]
        shown[run, "listed speed"] = cells[heads.index("best speed (cm/s)")]
        page.goto(f"{judged_server.url}/#/run/{run}/trial/{trial}")
        page.wait_for_selector("#judged-cot")
        shown[(run, trial)] = page.locator("#judged-cot").inner_text()
        ratio = page.locator("#verification tr", has_text="screen / judge ratio").locator("td")
        shown[(run, trial), "ratio"] = ratio.nth(1).inner_text() if ratio.count() else None
    page.close()
    assert shown["run-c"] == "5.5 judged" and shown[("run-c", 3)] == "6.6"
    assert shown[("run-c", 3), "ratio"] == "0.84"   # the screen's 0.21 m over the judge's 0.25 m
    assert shown["run-v8"] == f"2 screen's; judge's {NOT_MEASURED}" and shown[("run-v8", 1)] == NOT_MEASURED
    # the speed beside the judged distance is the judged one: 0.40 m over result()'s 5 s (the screen's: 2 cm/s)
    assert shown["run-c", "speed"] == shown["run-c", "listed speed"] == "8 judged"
    # the runs list gives the same COT beside the judged distance
    assert shown["run-c", "listed"] == "5.5 judged"
    assert shown["run-v8", "listed"] == f"2 screen's; judge's {NOT_MEASURED}"
