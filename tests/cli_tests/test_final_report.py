"""The report `spinefarm search` prints at the end: scores, verdict, file and next commands; parameters only
with --verbose."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def search(tmp_path: Path, *extra: str) -> str:
    out = tmp_path / "report.h5"
    r = subprocess.run([sys.executable, "-m", "spinefarm", "search", "sphere:40", "--trials", "12", "--workers", "1",
                        "--out", str(out), "--api-port", "-1", "--quiet", "--overwrite", *extra], cwd=ROOT,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    return r.stdout


def test_the_report_is_short_and_says_what_to_run_next(tmp_path: Path):
    text = search(tmp_path)
    lines = text.strip().splitlines()
    assert lines[0] == "search done: 12 parameter sets, 12 evaluations of sphere:40 (0 failed), run " \
        + lines[0].rsplit(" ", 1)[-1]
    assert lines[1].startswith("best trial ")
    assert "distance" in lines[2] and "cm/s" in lines[2] and "COT" in lines[2]
    assert lines[3].startswith("  verdict: ")
    assert f"file: {tmp_path / 'report.h5'}" in lines
    assert any(line.strip().startswith(f"spinefarm api {tmp_path / 'report.h5'}") for line in lines)
    assert "x17" not in text  # 40 parameters are not printed...
    assert "40 parameters: --verbose prints them" in text  # ...but it says where they are
    assert len(lines) <= 12 and max(len(line) for line in lines) < 100 + len(str(tmp_path / "report.h5"))


def test_verbose_lists_every_parameter_one_a_line(tmp_path: Path):
    lines = search(tmp_path, "--verbose").splitlines()
    shown = [line.split()[0] for line in lines if line.startswith("    x")]
    assert shown == [f"x{i}" for i in range(40)]
