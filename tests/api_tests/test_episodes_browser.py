"""A robust trial's page in a real browser shows its episodes and their spread."""

from __future__ import annotations

import json
import urllib.request

import pytest

from tests.api_tests.test_dashboard_browser import ARTIFACTS, Server, free_port, spinefarm

pytestmark = pytest.mark.integration


def test_the_trial_page_shows_each_episode_and_the_spread(browser, tmp_path):
    out = tmp_path / "robust.h5"
    spinefarm("search", "tetraspine", "--trials", "2", "--workers", "1", "--duration", "0.3", "--episodes", "3",
              "--randomize", "friction=0.1,start_jitter_cm=0.5", "--robust", "min", "--no-verify",
              "--run-id", "robust-view", "--api-port", "-1", "--quiet", "--out", str(out), "--engine", "bullet")
    port = free_port()
    server = Server(["api", str(out), "--port", str(port)], port)
    try:
        with urllib.request.urlopen(f"{server.url}/runs/robust-view/trials/1/episodes") as resp:
            body = json.load(resp)
        page = browser.new_page()
        page.goto(server.url + "/#/run/robust-view/trial/1")
        page.wait_for_selector("#episode-spread")
        text = page.inner_text("#episode-spread")
        assert text.startswith("3 episodes") and "objective: min" in text
        median = body["spread"]["speed_cm_s"]["median"]
        assert f"speed median {float(f'{median:.4g}')}" in text  # JS: Number(v.toPrecision(4)).toString()
        assert page.locator("#episode-table tbody tr").count() == 3
        page.screenshot(path=str(ARTIFACTS / "trial-episodes.png"), full_page=True)
        page.close()
    finally:
        server.stop()
