"""Notes on a run and on a trial, over real HTTP from a real `spinefarm api`, kept in a file beside the run
file and never written into it; bad input refused with one line, and a damaged notes file left as it is."""

from __future__ import annotations

import hashlib
import json
import urllib.error
import urllib.request

import pytest

from tests.api_tests.test_dashboard_browser import Server, free_port, spinefarm

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    d = tmp_path_factory.mktemp("notes")
    run = d / "sphere.h5"
    spinefarm("search", "sphere:3", "--trials", "5", "--workers", "1", "--out", str(run), "--run-id", "noted",
              "--api-port", "-1", "--quiet")
    port = free_port()
    s = Server(["api", str(run), "--port", str(port)], port)
    yield s, run
    s.stop()


def call(url: str, method: str = "GET", body: dict | None = None) -> tuple[int, dict]:
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(url, data=data, method=method, headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=30) as r:
            return r.status, json.load(r)
    except urllib.error.HTTPError as e:
        return e.code, json.load(e)


def digest(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_notes_on_a_run_and_a_trial_live_beside_the_run_file(served):
    server, run = served
    base = f"{server.url}/runs/noted"
    before = digest(run)
    run.with_name("sphere.h5.notes.json").unlink(missing_ok=True)
    assert call(base + "/notes") == (200, {"run": "", "trials": {}})
    assert call(base + "/notes", "PUT", {"text": "first try, σ too large"})[0] == 200
    assert call(base + "/trials/3/notes", "PUT", {"text": "odd: check the seed"})[0] == 200
    assert call(base + "/trials/1/notes", "PUT", {"text": "fine"})[0] == 200
    assert call(base + "/trials/1/notes", "PUT", {"text": ""})[0] == 200  # an empty note removes it
    want = {"run": "first try, σ too large", "trials": {"3": "odd: check the seed"}}
    assert call(base + "/notes") == (200, want)
    sidecar = run.with_name("sphere.h5.notes.json")
    assert json.loads(sidecar.read_text(encoding="utf-8")) == {"format": "spinefarm-notes/1", **want}
    assert digest(run) == before  # the run file is never written


def test_bad_notes_are_refused_by_name_and_a_damaged_notes_file_is_kept(served):
    server, run = served
    base = f"{server.url}/runs/noted"
    status, body = call(base + "/trials/99/notes", "PUT", {"text": "x"})
    assert status == 404 and body["detail"]["message"] == "no such trial; received 99; expected a trial id below 5"
    status, body = call(base + "/notes", "PUT", {"text": "x" * 20_001})
    assert status == 422 and "at most 20000 characters" in body["detail"]["message"]
    status, body = call(base + "/notes", "PUT", {"note": "x"})
    assert status == 422 and body["detail"]["message"].startswith("body.text: Field required")
    sidecar = run.with_name("sphere.h5.notes.json")
    sidecar.write_text("{not json")
    for method, body in (("GET", None), ("PUT", {"text": "would replace it"})):
        status, answer = call(base + "/notes", method, body)
        assert status == 409 and "the notes file cannot be read (JSONDecodeError); it is left as it is" in \
            answer["detail"]["message"], answer
    assert sidecar.read_text() == "{not json"
    sidecar.unlink()


def test_the_dashboard_keeps_a_note_on_the_run_page_and_on_a_trial_page(browser, served):
    server, run = served
    before = digest(run)
    ctx = browser.new_context(viewport={"width": 1280, "height": 800})
    page = ctx.new_page()
    try:
        for where, title, text in (("#/run/noted", "#run-title", "a run worth keeping"),
                                   ("#/run/noted/trial/2", "#trial-title", "trial 2: the best?")):
            page.goto(f"{server.url}/{where}")
            page.wait_for_selector(f"{title} >> nth=0", timeout=60_000)  # the page itself, not the one before
            page.wait_for_selector("#notes-text", timeout=60_000)
            page.fill("#notes-text", text)
            page.click("#notes-save")
            page.wait_for_selector("#notes-panel[data-saved='1']", timeout=30_000)
            assert page.locator("#notes-state").inner_text() == "saved"
            page.reload()
            page.wait_for_selector("#notes-text", timeout=60_000)
            assert page.locator("#notes-text").input_value() == text
    finally:
        ctx.close()
    assert call(f"{server.url}/runs/noted/notes")[1] == {"run": "a run worth keeping",
                                                         "trials": {"2": "trial 2: the best?"}}
    assert digest(run) == before
    run.with_name("sphere.h5.notes.json").unlink()
