"""A co-designed run in Chromium: its body constants are among the parallel coordinates' default axes, every one
has a bar in the importance chart (however weak, in their own colour), and the contour's default pair is the
strongest body constant against the strongest gait parameter (docs/codesign.md)."""

from __future__ import annotations

import textwrap

import pytest

from spinefarm.storage.hdf5_reader import read_run
from tests.api_tests.test_dashboard_browser import ARTIFACTS, Server, free_port, spinefarm

pytestmark = pytest.mark.integration

# NTRT's three-segment Tetraspine: 116 gait parameters, so by importance alone 3 body constants of 119 would
# rarely make the 8 default axes
SPEC = textwrap.dedent("""\
    base: tetraspine-ntrt
    name: co-spine
    search:
      segments.rod_length_scale: [0.7, 1.3]
      string_materials.outer.stiffness_n_per_m: [700, 1300]
      rod_materials.rod.density_kg_per_cm3: [0.0098, 0.0182]
    """)
BODY = ["body.segments.rod_length_scale", "body.string_materials.outer.stiffness_n_per_m",
        "body.rod_materials.rod.density_kg_per_cm3"]


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    d = tmp_path_factory.mktemp("codesign-views")
    (d / "co.yaml").write_text(SPEC)
    spinefarm("search", str(d / "co.yaml"), "--engine", "mujoco", "--trials", "8", "--workers", "1", "--duration",
              "0.2", "--out", str(d / "co.h5"), "--run-id", "co-run", "--api-port", "-1", "--quiet", "--seed", "2")
    port = free_port()
    server = Server(["api", "--runs-dir", str(d), "--port", str(port)], port)
    yield server, d / "co.h5"
    server.stop()


def test_body_constants_in_parallel_coordinates_importance_and_contour(browser, served):
    server, path = served
    meta, _ = read_run(path)
    assert [n for n in meta.param_names if n.startswith("body.")] == BODY and meta.n_params == 116 + 3
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(f"{server.url}/#/run/co-run")
    page.wait_for_selector("#pc-svg .pc-axis")
    page.wait_for_selector("#contour-svg, #contour-empty")
    axes = page.eval_on_selector_all("#pc-svg .pc-axis", "gs => gs.map(g => g.dataset.key)")
    # 8 default axes: the 3 body constants and 5 gait parameters (in the run's order), then the objective
    assert len(axes) == 9 and axes[-1] == "__objective"
    assert [a for a in axes if a.startswith("body.")] == BODY
    assert sum(not a.startswith(("body.", "__")) for a in axes) == 5
    bars = page.evaluate("() => document.getElementById('plot-importance').data[0].y")
    assert set(BODY) <= set(bars) and 30 <= len(bars) <= 33  # the 30 strongest, and any body constant beyond
    assert "the 3 body constants in orange" in page.inner_text("#importance-note")
    x = page.eval_on_selector("#contour-x", "s => s.value")
    y = page.eval_on_selector("#contour-y", "s => s.value")
    assert x in BODY and not y.startswith("body.")
    page.screenshot(path=str(ARTIFACTS / "run-codesign-views.png"), full_page=True)
    assert not errors, errors
    page.close()
