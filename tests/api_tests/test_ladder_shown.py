"""The status and the dashboard name the run's screening ladder and why it is this one: a real short search of a
user's spec file with a `ladder:` block of its own (`--engine auto`: the tetrahedral complex's shipped
calibration chooses MuJoCo at once, so its rungs are the file's), and of the same file with typed `--rungs` and
`--eta` (auto still chooses the engine, but not the rungs); the API over their run files (real HTTP), a browser
over `spinefarm api`."""

from __future__ import annotations

import pytest

from spinefarm.api.app import create_app
from tests.api_tests.test_dashboard_browser import Server, free_port, spinefarm
from tests.http_server import served

pytestmark = pytest.mark.integration

# the file's ladder: a sixth, a half and the whole of a 1.2 s trial at eta 2 -> 0.2, 0.6 and 1.2 s
OWN = {"rungs": "0.2,0.6,1.2", "eta": 2, "reason": "the robot's ladder, mine.yaml", "engine_auto": True}
TYPED = {"rungs": "0.5,1", "eta": 3, "reason": "typed (--rungs)", "engine_auto": False}


@pytest.fixture(scope="module")
def ladder_runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("ladders")
    spec = tmp_path_factory.mktemp("robot") / "mine.yaml"
    # the tetrahedral complex itself, name and all (its shipped calibration answers), with a ladder of its own
    spec.write_text("base: tetrahedral-complex\nladder:\n  rungs: [1/6, 1/2, 1]\n  eta: 2\n")
    spinefarm("search", str(spec), "--engine", "auto", "--trials", "3", "--duration", "1.2", "--workers", "2",
              "--out", str(d / "mine.h5"), "--run-id", "own-ladder", "--api-port", "-1", "--quiet", "--no-verify")
    spinefarm("search", str(spec), "--engine", "auto", "--rungs", "0.5,1", "--eta", "3", "--trials", "3", "--workers",
              "2", "--out", str(d / "typed.h5"), "--run-id", "typed-ladder", "--api-port", "-1", "--quiet",
              "--no-verify")
    return d


def test_the_status_names_the_ladder_and_why(ladder_runs):
    with served(create_app(runs_dir=ladder_runs)) as c:
        own, typed = c.get("/runs/own-ladder").json(), c.get("/runs/typed-ladder").json()
        listed = {r["run_id"]: r["ladder"] for r in c.get("/runs").json()}
    assert own["ladder"] == OWN and typed["ladder"] == TYPED
    assert listed == {"own-ladder": OWN, "typed-ladder": TYPED}
    assert own["rungs_s"] == [0.2, 0.6, 1.2] and typed["rungs_s"] == [0.5, 1.0]   # the older key stays


def test_the_dashboard_shows_the_ladder_beside_the_engine_choice(ladder_runs, browser):
    port = free_port()
    server = Server(["api", "--runs-dir", str(ladder_runs), "--port", str(port)], port)
    try:
        shown = {}
        for run in ("own-ladder", "typed-ladder"):
            page = browser.new_page()  # a fresh page each: the last run's cards are not this one's
            page.goto(f"{server.url}/#/run/{run}")
            page.wait_for_selector("#ladder")
            shown[run] = (page.locator("#ladder .v").inner_text(), page.inner_text("#ladder-reason"),
                          page.locator("[data-engine-choice]").count())
            page.close()
    finally:
        server.stop()
    assert shown["own-ladder"] == ("rungs 0.2,0.6,1.2 s, eta 2", "the robot's ladder, mine.yaml", 1)
    assert shown["typed-ladder"] == ("rungs 0.5,1 s, eta 3", "typed (--rungs)", 1)
