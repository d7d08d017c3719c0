"""Model spread in every report: a judged best's distance in the other engine (an evaluation row of kind
"opinion") beside the judge's, their ratio and each engine's step error, in the final report, `/runs/ID/best`
and `/runs/ID/trials/ID` (the trial page's source). The rows are written into a real run file through the
storage API, as the coordinator stores a judge's and an opinion's runs."""

from __future__ import annotations

import pytest

from spinefarm.api.app import create_app
from spinefarm.cli.report import final_report, verdict_text
from spinefarm.protocol.engine_choice import EngineChoice
from spinefarm.protocol.states import TrialStatus
from spinefarm.storage.evaluations import row_of
from spinefarm.storage.hdf5 import Hdf5Storage
from tests.api_tests.judged import judged_run
from tests.http_server import served
from tests.storage_tests.conftest import result

SCREEN_M = [0.05, 0.30, 0.02, 0.21, 0.03]  # MuJoCo screens; trial 1 is best, trial 3 next
JUDGE_M = {1: 0.40, 3: 0.25}  # Bullet at 0.25 ms judges both
OPINION_M = {1: 0.32}  # MuJoCo at 0.5 ms, a second opinion on trial 1; trial 3 has none
# per engine, the calibration's median change of a distance at half the step
STEP_ERROR = {"mujoco": 0.017, "bullet": 0.046}


def _judged_run(path, opinion_fails: bool = False):
    choice = EngineChoice(engine="mujoco", spearman=0.95, top_overlap=9, top_k=10, median_distance_ratio=1.0,
                          tiers={t: {"cpu_s_per_sim_s": 0.1, "step_error": e} for t, e in STEP_ERROR.items()})
    with judged_run(path, "run-s", {t: result(t, d) for t, d in enumerate(SCREEN_M)},
                    {t: result(t, d) for t, d in JUDGE_M.items()}, engine_choice=choice) as s:
        for tid, d in OPINION_M.items():
            r = result(tid, d, status=TrialStatus.FAILED, reason="diverged") if opinion_fails else result(tid, d)
            s.add_evaluation(row_of(tid, "opinion", r, "mujoco", 5e-4, "w-opinion"))


def test_best_and_the_trial_page_serve_both_distances_their_ratio_and_the_step_errors(tmp_path):
    _judged_run(tmp_path / "s.h5")
    with served(create_app(runs_dir=tmp_path)) as c:
        best = c.get("/runs/run-s/best", params={"k": 2}).json()
        page = c.get("/runs/run-s/trials/1").json()
        unjudged = c.get("/runs/run-s/trials/0").json()
    assert [b["trial_id"] for b in best] == [1, 3]  # ranked by the judged distance: 0.40, 0.25
    spread = best[0]["model_spread"]
    assert page["model_spread"] == spread
    assert spread["judge"]["engine"] == "bullet" and spread["judge"]["dt_s"] == 2.5e-4
    assert spread["judge"]["distance_m"] == 0.40 and spread["judge"]["worker_id"] == "w-judge"
    assert spread["other"]["engine"] == "mujoco" and spread["other"]["dt_s"] == 5e-4
    assert spread["other"]["distance_m"] == 0.32 and spread["other"]["worker_id"] == "w-opinion"
    assert abs(spread["ratio"] - 0.8) < 1e-12  # 0.32 / 0.40
    assert spread["step_error"] == STEP_ERROR
    assert best[1]["model_spread"] is None and unjudged["model_spread"] is None  # no opinion row on them


def test_the_final_report_prints_the_spread_beside_the_step_errors(tmp_path):
    _judged_run(tmp_path / "s.h5")
    with Hdf5Storage.open_read(tmp_path / "s.h5") as s:
        b = s.best(1)[0]
        text = final_report(s, tmp_path / "s.h5", verdict=verdict_text(b, "bullet"), done=True)
    [line] = [x for x in text.splitlines() if "model spread" in x]
    assert line.strip() == ("model spread: judge bullet at 0.25 ms 0.4 m, other engine mujoco at 0.5 ms 0.32 m, "
                            "ratio 0.8 (step error bullet 4.6 %, mujoco 1.7 %)")


def test_a_failed_opinion_is_shown_as_failed_with_no_ratio(tmp_path):
    _judged_run(tmp_path / "s.h5", opinion_fails=True)
    with served(create_app(runs_dir=tmp_path)) as c:
        spread = c.get("/runs/run-s/best", params={"k": 1}).json()[0]["model_spread"]
    assert spread["other"]["status"] == "failed" and spread["other"]["reason"] == "diverged"
    assert spread["ratio"] is None
    with Hdf5Storage.open_read(tmp_path / "s.h5") as s:
        text = final_report(s, tmp_path / "s.h5", verdict="", done=True)
    assert "other engine mujoco at 0.5 ms failed (diverged), ratio -" in text


@pytest.mark.integration
def test_the_trial_page_shows_both_distances_their_ratio_and_the_step_errors(browser, tmp_path):
    from tests.api_tests.test_dashboard_browser import Server, free_port

    _judged_run(tmp_path / "s.h5")
    port = free_port()
    server = Server(["api", "--runs-dir", str(tmp_path), "--port", str(port)], port)
    try:
        page = browser.new_page()
        page.goto(server.url + "/#/run/run-s/trial/1")
        page.wait_for_selector("#spread-ratio")
        shown = {k: page.locator(f"#spread-{k}").inner_text() for k in ("judge", "other", "ratio", "step-error")}
        label = page.locator("#verification tr", has_text="other engine").locator("td").first.inner_text()
        page.close()
    finally:
        server.stop()
    assert float(shown["judge"]) == 0.40 and float(shown["other"]) == 0.32 and float(shown["ratio"]) == 0.8
    assert shown["step-error"] == "bullet 4.6 %, mujoco 1.7 %" and "mujoco at 0.5 ms" in label
