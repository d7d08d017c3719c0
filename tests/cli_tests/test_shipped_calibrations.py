"""The built-ins' shipped calibrations (spinefarm/robot/calibrations/, `python bench/ship_calibrations.py`):
each is for its built-in as the spec stands, against the judge, and is what `spinefarm calibrate NAME --json`
and `search --engine auto` use without calibrating. A failure here after a change of a built-in's spec means
its file must be re-created (docs/engines.md)."""

from __future__ import annotations

import json
import subprocess
import sys

from spinefarm.robot.morphology.registry import builtin_names, load_morphology
from spinefarm.storage.hdf5_reader import read_run
from spinefarm.worker.tools.shipped_calibration import SHIPPED_DIR
from tests.coordinator_tests.procs import ROOT

SHIPPED_FIRST = {"tetrahedral-complex", "tetraspine"}  # the two docs/engines.md quotes


def spinefarm(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "spinefarm", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=300)


def _passes(d: dict) -> bool:
    """The rule by its documented thresholds: rho >= 0.9, top-10 overlap >= 8, ratio within [0.9, 1.1]."""
    ratio = d["median_distance_ratio"]
    return (d["spearman"] is not None and d["spearman"] >= 0.9 and d["top_overlap"] >= 8 and d["top_k"] == 10
            and ratio is not None and 0.9 <= ratio <= 1.1)


def test_each_shipped_file_is_its_builtin_against_the_judge():
    files = {f.stem: json.loads(f.read_text()) for f in SHIPPED_DIR.glob("*.json")}
    # every built-in starts searching at once
    assert set(files) == set(builtin_names()), sorted(set(builtin_names()) ^ set(files))
    for name, d in files.items():
        assert d["robot"] == name and d["spec_hash"] == load_morphology(name).spec_hash(), name
        assert d["reference"]["engine"] == "bullet" and d["reference"]["judge_dt_s"] == 0.00025, name
        s = d["settings"]  # the defaults of `spinefarm calibrate`, not a smaller calibration
        assert (s["gaits"], s["search_trials"], s["bests"], s["duration_s"], s["settle_s"]) == (40, 40, 10, 5.0, 1.0)
        assert len(d["distance_m"]["bullet"]) == 50 and s["profile"] == []
        assert d["decision"] == ("mujoco" if _passes(d) else "bullet"), name


def test_calibrate_answers_from_the_shipped_file_without_a_trial(tmp_path):
    for name in sorted(SHIPPED_FIRST):
        r = spinefarm("calibrate", name, "--json")
        assert r.returncode == 0, r.stderr[-2000:]
        out = json.loads(r.stdout.strip().splitlines()[-1])
        d = json.loads((SHIPPED_DIR / f"{name}.json").read_text())
        assert out["shipped"] is True and out["cached"] is True and "trials" not in r.stderr
        assert out["decision"] == d["decision"] and out["distance_m"] == d["distance_m"]


def test_search_engine_auto_takes_the_shipped_choice(tmp_path):
    out = tmp_path / "auto.h5"
    r = spinefarm("search", "tetrahedral-complex", "--trials", "1", "--workers", "1", "--duration", "0.3",
                  "--out", str(out), "--api-port", "-1", "--quiet", "--no-verify")
    assert r.returncode == 0, r.stderr[-2000:]
    assert "calibrating" not in r.stderr
    d = json.loads((SHIPPED_DIR / "tetrahedral-complex.json").read_text())
    choice = read_run(out)[0].settings.engine_choice.to_dict()
    assert choice["engine"] == d["decision"] and choice["spec_hash"] == d["spec_hash"]
    assert choice["spearman"] == d["spearman"] and choice["cached"] is True and choice["shipped"] is True
    assert "[shipped calibration]" in r.stderr and "[calibration cached]" not in r.stderr  # says where it came from
    assert choice["screen_fit"] is None  # a built-in's shipped choice stands as made; nothing was fitted
