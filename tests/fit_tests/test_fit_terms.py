"""The window error's terms (worker.fit.terms): by Pythagoras they add up to the window error, and a share is
each term's part of the squared error."""

from __future__ import annotations

import pytest

from spinefarm.cli.main import main
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.fit.loss import prepare, window_error_cm
from spinefarm.worker.fit.readers import read_recording
from spinefarm.worker.fit.terms import term_shares, window_terms


def test_terms_add_up_to_the_window_error(tmp_path):
    """Recorded at ground friction 0.4, simulated at the model's 1.0: the squared terms (horizontal, vertical,
    rotation arc), averaged over windows of equal sample counts, are the window error squared."""
    (tmp_path / "p.yaml").write_text("constants: {ground_friction: 0.4}\n")
    assert main(["trial", "tetraspine-ntrt", "--random-seed", "2", "--duration", "0.3", "--engine", "mujoco",
                 "--record", str(tmp_path / "r.npz"), "--record-every", "0.001", "--profile",
                 str(tmp_path / "p.yaml"), "--json"]) in (0, 1)
    morph, cfg = load_morphology("tetraspine-ntrt"), TrialConfig(engine="mujoco")
    p = prepare("r", read_recording(tmp_path / "r.npz"), 0.1, 0.1)
    rows = window_terms(morph, cfg, p)
    assert len(rows) == 3 and len({len(w.rows) for w in p.windows}) == 1
    assert [r["start_s"] for r in rows] == pytest.approx([0.0, 0.1, 0.2], abs=1e-9)
    mean_sq = sum(r["horizontal_cm"] ** 2 + r["vertical_cm"] ** 2 + r["rotation_cm"] ** 2 for r in rows) / 3
    assert mean_sq ** 0.5 == pytest.approx(window_error_cm(morph, cfg, [p]), rel=1e-9)
    assert all(r["horizontal_cm"] > 0 and r["rotation_cm"] > 0 for r in rows)


def test_shares_are_parts_of_the_squared_error():
    rows = [{"horizontal_cm": 3.0, "vertical_cm": 4.0, "rotation_cm": 0.0, "tension_n": 1.0},
            {"horizontal_cm": 0.0, "vertical_cm": 0.0, "rotation_cm": 5.0, "tension_n": 1.0}]
    assert term_shares(rows) == pytest.approx({"horizontal_cm": 9 / 50, "vertical_cm": 16 / 50, "rotation_cm": 0.5})
