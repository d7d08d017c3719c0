"""Target 2 of the co-design at a smaller size (docs/codesign.md): a co-designed search on 2 workers over a range
that admits infeasible bodies loses nothing to them. Every trial of the budget is complete or failed as
`infeasible:` with its reason, each reason one of the body check's, and the run ends done."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import spinefarm

ROOT = Path(__file__).resolve().parents[2]
TRIALS = 60
# the paper's Tetraspine, rod lengths and masses +-30 %, segments drawn 5 % to 130 % of their spacing: below
# about 20 % rods of neighbouring segments pass through each other, and some closer bodies find no stable step
SPEC = textwrap.dedent("""\
    base: tetraspine
    name: codesign-tetraspine
    search:
      segments.rod_length_scale: [0.7, 1.3]
      segments.spacing_scale: [0.05, 1.3]
      rod_materials.rod.density_kg_per_cm3: [0.0098, 0.0182]
    """)
# the body check's reasons (worker.trial.feasibility, the table in docs/codesign.md)
REASONS = ("does not build:", "rods through each other:", "strings cannot hold their pretension:",
           "no stable step:", "no rest shape:", "strings slack:")


@pytest.mark.slow
def test_a_codesigned_search_on_two_workers_loses_nothing_to_infeasible_bodies(tmp_path):
    (tmp_path / "co.yaml").write_text(SPEC)
    out = tmp_path / "co.h5"
    # the paper's sampler: its Monte Carlo half draws bodies across the whole range, the close ones too
    r = subprocess.run([sys.executable, "-m", "spinefarm", "search", str(tmp_path / "co.yaml"), "--trials",
                        str(TRIALS), "--workers", "2", "--duration", "0.5", "--engine", "mujoco", "--dt", "0.002",
                        "--engine-option", "segment_contacts=off", "--sampler", "paper", "--seed", "3",
                        "--api-port", "-1", "--quiet", "--out", str(out)],
                       cwd=ROOT, capture_output=True, text=True, timeout=1800)
    assert r.returncode == 0, r.stderr
    df = spinefarm.load_run(out)
    assert len(df) == TRIALS and set(df["status"]) <= {"complete", "failed"}
    failed = df[df["status"] == "failed"]
    assert len(failed) >= 1, "the range admits infeasible bodies: some must have been drawn"
    for reason in failed["reason"]:
        assert reason.startswith("infeasible: ") and reason[len("infeasible: "):].startswith(REASONS), reason
    # a body too close to build is refused for its rods, never run: each such trial had spacing under 20 %
    crossing = failed[failed["reason"].str.startswith("infeasible: rods through each other")]
    assert (crossing["body.segments.spacing_scale"] < 0.2).all()
    assert "search done" in r.stdout and "co-designed: the calibration covers none" in r.stdout
