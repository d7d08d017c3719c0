"""The gait, moving: a trial's recorded motion played in 3D in a real browser (Playwright + Debian's chromium)
over a run file written by a real search, with every request logged."""

from __future__ import annotations

import json
import urllib.request

import numpy as np
import pytest

from spinefarm.robot.bodies import build_bodies, build_strings
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.storage.hdf5_reader import read_run
from spinefarm.worker.tools.render import rod_segments, string_segments
from tests.api_tests.test_dashboard_browser import ARTIFACTS, Server, free_port, spinefarm
from tests.coordinator_tests.helpers import wait_for

pytestmark = pytest.mark.integration

MOTION_TIMEOUT_MS = 240_000


@pytest.fixture(scope="module")
def run_file(tmp_path_factory):
    """A robot from a user's spec file (a built-in's, under its own name, with 5 segments instead of 12)."""
    d = tmp_path_factory.mktemp("motion")
    text = spinefarm("spec", "tetraspine", "--name", "five-spine").stdout
    assert "  count: 12\n" in text
    (d / "five.yaml").write_text(text.replace("  count: 12\n", "  count: 5\n", 1))
    spinefarm("search", str(d / "five.yaml"), "--trials", "2", "--workers", "1", "--engine", "bullet",
              "--duration", "1", "--out", str(d / "five.h5"), "--run-id", "tetra-motion", "--api-port", "-1", "--quiet",
              "--no-verify")
    return d / "five.h5"


@pytest.fixture(scope="module")
def server(run_file, tmp_path_factory):
    port = free_port()
    s = Server(["api", str(run_file), "--port", str(port)], port)
    yield s
    s.stop()


@pytest.fixture
def page(browser, server):
    ctx = browser.new_context(viewport={"width": 1400, "height": 900})
    pg = ctx.new_page()
    pg.requests, pg.errors = [], []
    pg.on("request", lambda r: pg.requests.append(r.url))  # every request, also those a policy would stop
    pg.on("pageerror", lambda e: pg.errors.append(str(e)))
    pg.on("console", lambda m: m.type == "error" and pg.errors.append(m.text))
    yield pg
    assert not pg.errors, pg.errors
    ctx.close()


def foreign(page, server) -> list[str]:
    """Requests that left this server (a blob: of its own page, the gait picture, stays in the browser)."""
    return [u for u in page.requests if not u.startswith((server.url, "blob:" + server.url))]


def motion_of(server, trial_id: int) -> dict:
    with urllib.request.urlopen(f"{server.url}/runs/tetra-motion/trials/{trial_id}/motion.json", timeout=300) as r:
        return json.loads(r.read())


def drawn(page, k: int = 0) -> dict:
    return page.evaluate(f"""() => {{ const v = document.getElementById('motion-{k}').motionView;
        return {{frame: v.frame, rods: v.rodEnds(), strings: v.stringEnds()}}; }}""")


def test_the_motion_is_the_stored_trial(server, run_file):
    meta, cols = read_run(run_file)
    m = motion_of(server, 1)
    morph = load_morphology(meta.morphology_spec)
    assert m["format"] == "spinefarm-motion/1" and m["n_bodies"] == morph.structure.n_segments == 5
    assert m["morphology"] == meta.morphology == "five-spine"
    assert len(m["strings"]) == len(morph.structure.strings)
    t = np.array(m["time_s"])
    assert t[0] == 0.0 and t[-1] == pytest.approx(1.0) and np.all(np.diff(t) > 0)
    assert len(t) == pytest.approx(31, abs=2)  # 30 frames a second
    # re-simulated as the search ran it: the same distance as stored
    assert m["result"]["distance_m"] == pytest.approx(cols["distance_m"][1], rel=1e-6)


def test_the_3d_view_plays_from_local_assets_and_shows_the_recorded_frame(page, server, run_file):
    meta, _ = read_run(run_file)
    page.goto(server.url + "/#/run/tetra-motion/trial/1")
    page.wait_for_selector("#motion-area[data-ready]", timeout=MOTION_TIMEOUT_MS)
    assert page.locator("#motion-0 canvas").count() == 1
    assert page.evaluate("() => !!document.querySelector('#motion-0 canvas').getContext('webgl2')")
    # it plays when opened: time and frame move on by themselves, then stop on pause
    assert page.locator("#motion-bar").get_attribute("data-playing") == "1"
    page.select_option("#motion-speed", "0.25")  # a 1 s trial plays in 4 s
    wait_for(lambda: page.evaluate("() => document.getElementById('motion-0').motionView.frame") >= 6,
             timeout_s=20, poll_s=0.05, what="the motion to play")
    page.click("#motion-play")
    assert page.locator("#motion-bar").get_attribute("data-playing") == "0"
    # paused: the clock stands still (it may have looped past the end if the browser stalled, so no bound on it)
    paused_at = page.locator("#motion-bar").get_attribute("data-time")
    page.wait_for_timeout(300)
    assert page.locator("#motion-bar").get_attribute("data-time") == paused_at
    # the frame shown at 0.5 s is the recorded one: rods and strings where the recorded poses put them
    page.evaluate("window.spinefarmPlayer.seek(0.5)")
    m = motion_of(server, 1)
    i = int(np.searchsorted(np.array(m["time_s"]), 0.5, side="right") - 1)
    shown = drawn(page)
    assert shown["frame"] == i
    morph = load_morphology(meta.morphology_spec)
    bodies = build_bodies(morph.structure)
    poses = np.array(m["poses"][i]).reshape(-1, 7)
    expected_rods = rod_segments(bodies, poses).reshape(-1, 6)
    expected_strings = string_segments(build_strings(morph.structure, bodies), poses).reshape(-1, 6)
    assert np.abs(np.array(shown["rods"]) - expected_rods).max() < 0.02      # cm
    assert np.abs(np.array(shown["strings"]) - expected_strings).max() < 0.02
    assert np.abs(expected_rods - rod_segments(bodies, np.array(m["poses"][0]).reshape(-1, 7)).reshape(-1, 6)
                  ).max() > 0.1  # and the robot did move between frame 0 and then
    # the strip of six frames below is drawn from the same recorded motion (no second re-simulation)
    page.wait_for_selector("#gait", timeout=MOTION_TIMEOUT_MS)
    assert page.evaluate("document.getElementById('gait').naturalWidth") > 400
    page.screenshot(path=ARTIFACTS / "trial-motion.png", full_page=True)
    assert not foreign(page, server), foreign(page, server)


def test_two_trials_side_by_side_in_step(page, server):
    page.goto(server.url + "/#/run/tetra-motion/watch/0,1")
    page.wait_for_selector("#motion-area[data-ready]", timeout=MOTION_TIMEOUT_MS)
    assert page.locator(".motion canvas").count() == 2
    page.evaluate("window.spinefarmPlayer.pause(); window.spinefarmPlayer.seek(0.7)")  # it plays when opened
    times = [float(page.locator(f"#motion-{k}").get_attribute("data-time")) for k in (0, 1)]
    assert times[0] == times[1] == pytest.approx(0.7, abs=1 / 30)
    a, b = drawn(page, 0), drawn(page, 1)
    assert np.abs(np.array(a["rods"]) - np.array(b["rods"])).max() > 0.1  # two different gaits
    page.screenshot(path=ARTIFACTS / "trials-side-by-side.png", full_page=True)
    assert not foreign(page, server), foreign(page, server)


def test_without_the_simulator_the_3d_view_says_so(browser, run_file):
    port = free_port()
    s = Server(["api", str(run_file), "--port", str(port)], port,
               prelude="import sys; sys.modules['pybullet'] = None")  # as if pybullet were not installed
    try:
        page = browser.new_page()
        page.goto(s.url + "/#/run/tetra-motion/trial/0")
        page.wait_for_selector("#motion-error")
        assert "simulator is not installed" in page.locator("#motion-error").inner_text()
        with pytest.raises(urllib.error.HTTPError) as err:
            urllib.request.urlopen(f"{s.url}/runs/tetra-motion/trials/0/motion.json", timeout=30)
        assert err.value.code == 503
        page.close()
    finally:
        s.stop()


def test_a_picture_cache_folder_that_cannot_be_made_draws_in_a_temporary_one(run_file, tmp_path, caplog):
    """A read-only home or a mistyped SPINEFARM_CACHE_DIR: the gait is still drawn (it was a 500)."""
    from spinefarm.api.app import create_app
    from tests.http_server import served

    blocked = tmp_path / "a-file"
    blocked.write_text("x")  # no folder can be made below a file
    with served(create_app([run_file], picture_cache_dir=blocked / "pictures")) as client:
        r = client.get("/runs/tetra-motion/trials/0/motion.json")
        assert r.status_code == 200, r.text
        assert r.json()["format"] == "spinefarm-motion/1" and len(r.json()["time_s"]) > 1
    assert any("cannot keep gait pictures in" in m and "drawing them in" in m for m in caplog.messages)


def test_a_full_picture_cache_is_an_error_in_words(run_file, tmp_path):
    """A full disk under the picture cache (a real tmpfs, filled): a JSON error naming it, not a traceback."""
    import subprocess

    from spinefarm.api.app import create_app
    from tests.http_server import served

    mnt = tmp_path / "fs"
    mnt.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(mnt)], capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs to fill up (needs root): {r.stderr.strip()}")
    try:
        (mnt / "pictures").mkdir()
        with open(mnt / "filler", "wb", buffering=0) as fh:  # every block taken
            try:
                while True:
                    fh.write(b"\0" * 4096)
            except OSError:
                pass
        with served(create_app([run_file], picture_cache_dir=mnt / "pictures")) as client:
            r = client.get("/runs/tetra-motion/trials/0/motion.json")
        assert r.status_code == 500, r.text
        detail = r.json()["detail"]
        assert detail["code"] == "render_failed" and "No space left on device" in detail["message"], detail
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)
