"""A judged best's cost of transport is the judge's: every evaluation row keeps the COT its run measured, and
the final report, `/runs/ID`, `/runs/ID/best`, `/runs/ID/trials/ID` and the dashboard show the judge's COT beside
its distance (the screen's apart), and the dashboard the judged speed. A run file of schema 8
(tests/storage_tests/data/run-schema8.h5, written by spinefarm at ce6864d: four trials with screen COTs 1, 2, 3
and 4; trials 1 and 3 judged in Bullet, an opinion and an audit on trial 1) has no such column: it opens
everywhere and says "not measured".

The rows here are written through the storage API as the coordinator stores them; the real search whose judged
COT is held against an independent `spinefarm trial` is tests/coordinator_tests/test_judged_cot_search.py."""

from __future__ import annotations

import dataclasses
import math
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from spinefarm.api.app import create_app
from spinefarm.cli.report import final_report
from spinefarm.protocol.settings import JudgePolicy, Rung
from spinefarm.protocol.states import AuditState, Verification
from spinefarm.storage.evaluations import NOT_MEASURED, row_of
from spinefarm.storage.hdf5 import Hdf5Storage
from spinefarm.storage.schema import FILE_SCHEMA_VERSION
from tests.http_server import served
from tests.storage_tests.conftest import make_meta, result

OLD = Path(__file__).parents[1] / "storage_tests" / "data" / "run-schema8.h5"
SCREEN = {0: (0.05, 1.1), 1: (0.30, 2.2), 2: (0.02, 3.3), 3: (0.21, 4.4)}   # trial: (distance m, COT)
JUDGE = {1: (0.40, 5.5), 3: (0.25, 6.6)}     # Bullet at 0.25 ms judges trials 1 and 3
OPINION = {1: (0.32, 7.7)}                    # MuJoCo at 1 ms, the other engine's run of trial 1
AUDIT = {1: (0.30, 8.8)}                      # another worker, the screen's fidelity


def _ran(tid: int, distance_m: float, cot: float):
    return dataclasses.replace(result(tid, distance_m), cot=cot)


def _judged_run(path: Path) -> None:
    meta = make_meta("run-c", budget=4)
    meta = dataclasses.replace(meta, settings=dataclasses.replace(meta.settings, judge=JudgePolicy(
        rung=Rung("bullet", 2.5e-4))), run={**meta.run, "trial_config": {"duration_s": 0.5, "engine": "mujoco"}})
    s = Hdf5Storage.create(path, meta)
    for tid, (d, cot) in SCREEN.items():
        s.add_trial(tid, np.full(3, 0.5), np.zeros(3), "monte_carlo", -1, tid)
        s.finish_trial(tid, _ran(tid, d, cot), d)
    for tid, (d, cot) in JUDGE.items():
        s.add_evaluation(row_of(tid, "judge", _ran(tid, d, cot), "bullet", 2.5e-4, "w-judge"))
        s.set_verification(tid, Verification.JUDGED, d, "judged in bullet", SCREEN[tid][0] / d)
    for tid, (d, cot) in OPINION.items():
        s.add_evaluation(row_of(tid, "opinion", _ran(tid, d, cot), "mujoco", 1e-3, "w-opinion"))
    for tid, (d, cot) in AUDIT.items():
        s.add_evaluation(row_of(tid, "audit", _ran(tid, d, cot), "", None, "w-audit"))
        s.set_audit(tid, AuditState.AGREES, d, "w-audit")
    s.close()


def test_every_evaluation_row_keeps_its_cot_with_its_unit(tmp_path):
    _judged_run(tmp_path / "c.h5")
    with Hdf5Storage.open_read(tmp_path / "c.h5") as s:
        ev = s.evaluations()
    got = {(int(t), k.decode()): float(c) for t, k, c in zip(ev["trial_id"], ev["kind"], ev["cot"], strict=True)}
    assert got == {(1, "judge"): 5.5, (3, "judge"): 6.6, (1, "opinion"): 7.7, (1, "audit"): 8.8}
    with h5py.File(tmp_path / "c.h5", "r") as f:
        assert f["evaluations/cot"].attrs["unit"] == "1" and f.attrs["file_schema_version"] == FILE_SCHEMA_VERSION


def test_best_the_trial_page_and_the_run_show_the_judges_cot_not_the_screens(tmp_path):
    _judged_run(tmp_path / "c.h5")
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


def test_the_final_report_gives_the_judges_cot_beside_its_distance(tmp_path):
    _judged_run(tmp_path / "c.h5")
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
        resumed.add_evaluation(row_of(3, "opinion", _ran(3, 0.2, 9.9), "mujoco", 1e-3, "w-opinion"))
    finally:
        resumed.close()
    with h5py.File(path, "r") as f:
        assert f.attrs["file_schema_version"] == FILE_SCHEMA_VERSION
        cot = f["evaluations/cot"][:]
    assert np.isnan(cot[:4]).all() and cot[4] == 9.9 and not math.isnan(cot[4])


@pytest.mark.integration
def test_the_dashboard_and_the_trial_page_show_the_judges_cot(browser, tmp_path):
    from tests.api_tests.test_dashboard_browser import Server, free_port

    _judged_run(tmp_path / "c.h5")
    shutil.copy(OLD, tmp_path / "old.h5")
    port = free_port()
    server = Server(["api", "--runs-dir", str(tmp_path), "--port", str(port)], port)
    try:
        page = browser.new_page()
        shown = {}
        for run, trial in (("run-c", 3), ("run-v8", 1)):
            page.goto(f"{server.url}/#/run/{run}")
            page.wait_for_selector("#best-cot")
            shown[run] = page.locator("#best-cot").inner_text()
            shown[run, "speed"] = page.locator("#best-speed").inner_text()
            page.goto(f"{server.url}/#/")
            page.wait_for_selector(f"tr[data-run='{run}']")
            heads = page.locator("thead th").all_inner_texts()
            cells = page.locator(f"tr[data-run='{run}'] td").all_inner_texts()
            shown[run, "listed"] = cells[heads.index("best COT")]
            shown[run, "listed speed"] = cells[heads.index("best speed (cm/s)")]
            page.goto(f"{server.url}/#/run/{run}/trial/{trial}")
            page.wait_for_selector("#judged-cot")
            shown[(run, trial)] = page.locator("#judged-cot").inner_text()
        page.close()
    finally:
        server.stop()
    assert shown["run-c"] == "5.5 judged" and shown[("run-c", 3)] == "6.6"
    assert shown["run-v8"] == f"2 screen's; judge's {NOT_MEASURED}" and shown[("run-v8", 1)] == NOT_MEASURED
    # the speed beside the judged distance is the judged one: 0.40 m over result()'s 5 s (the screen's: 2 cm/s)
    assert shown["run-c", "speed"] == shown["run-c", "listed speed"] == "8 judged"
    # the runs list gives the same COT beside the judged distance
    assert shown["run-c", "listed"] == "5.5 judged"
    assert shown["run-v8", "listed"] == f"2 screen's; judge's {NOT_MEASURED}"
