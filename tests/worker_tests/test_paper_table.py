"""The paper's table, reduced: bench/paper_table.py's short form re-run here lands every shipped gait's median
speed and COT inside the ranges docs/results.md states for it."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import pytest

from tests.coordinator_tests.procs import ROOT

BLOCK = re.compile(r"<!-- paper_table bullet 4 s: begin -->(.*?)<!-- paper_table bullet 4 s: end -->", re.S)
RANGE = re.compile(r"\[([-0-9.]+), ([-0-9.]+)\]")


def stated() -> tuple[list[str], dict[str, tuple[tuple[float, float], tuple[float, float]]]]:
    """(the command docs name, gait -> (accepted speed range, accepted COT range))."""
    block = BLOCK.search((ROOT / "docs" / "results.md").read_text()).group(1)
    cmd = next(ln.strip() for ln in block.splitlines() if ln.strip().startswith("python bench/paper_table.py"))
    ranges = {}
    for line in block.splitlines():
        found = RANGE.findall(line)
        if line.startswith("| ") and len(found) == 2:
            (s0, s1), (c0, c1) = found
            ranges[line.split("|")[1].strip()] = ((float(s0), float(s1)), (float(c0), float(c1)))
    return cmd.split()[1:], ranges


def test_every_shipped_gait_lands_in_the_range_docs_state():
    args, ranges = stated()
    assert set(ranges) == {p.stem for p in (ROOT / "examples" / "gaits").glob("*.json")}
    args = [a for a in args if a != "--write-docs"]  # a check never rewrites the docs
    r = subprocess.run([sys.executable, *args], cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    result = json.loads(r.stdout.strip().splitlines()[-1])
    for gait, ((s0, s1), (c0, c1)) in ranges.items():
        got = result["spines"][gait]
        assert s0 <= got["median_speed_cm_s"] <= s1, (gait, got["median_speed_cm_s"], (s0, s1))
        assert c0 <= got["median_cot"] <= c1, (gait, got["median_cot"], (c0, c1))
        assert got["configs"]["bullet"]["failed"] == 0


def test_a_gait_of_a_subfolder_is_set_beside_its_spines_paper_figures():
    """examples/gaits/robust/tetraspine.json is the Tetraspine's: its row carries the Tetraspine's paper figures."""
    r = subprocess.run([sys.executable, "bench/paper_table.py", "--episodes", "1", "--duration", "0.5", "--configs",
                        "bullet", "--gaits", "robust/tetraspine", "--workers", "1"], cwd=ROOT, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    row = json.loads(r.stdout.strip().splitlines()[-1])["spines"]["robust/tetraspine"]
    assert (row["paper_speed_cm_s"], row["paper_cot"]) == (9.46, 3.2) and row["configs"]["bullet"]["failed"] == 0
    bad = subprocess.run([sys.executable, "bench/paper_table.py", "--gaits", "robust/nothing"], cwd=ROOT,
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode != 0 and "robust/nothing" in bad.stderr


def test_the_table_runs_on_the_scene_it_is_given():
    """--scene reaches every episode (a ground narrower than the robot: it falls off its edge) and the command
    that re-creates the table; a bad scene is refused once, by name."""
    r = subprocess.run([sys.executable, "bench/paper_table.py", "--episodes", "1", "--duration", "1", "--configs",
                        "bullet", "--gaits", "tetraspine", "--workers", "1",
                        "--scene", "flat,ground_half_extent_cm=10"],
                       cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    result = json.loads(r.stdout.strip().splitlines()[-1])
    assert result["scene"] == "flat,ground_half_extent_cm=10"
    assert result["rows"][0]["status"] == "failed"
    assert result["rows"][0]["reason"].startswith("fell off the ground's edge"), result["rows"][0]["reason"]
    sys.path.insert(0, str(ROOT / "bench"))
    import paper_table

    assert "--scene flat,ground_half_extent_cm=10" in paper_table.command(result)
    bad = subprocess.run([sys.executable, "bench/paper_table.py", "--gaits", "tetraspine", "--scene", "flat,width=3"],
                         cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert bad.returncode != 0 and "--scene: bad scene field; received 'width=3'" in bad.stderr


@pytest.mark.slow
def test_the_efficient_gaits_beat_the_papers_speed_and_cot_at_the_median():
    """docs/results.md, "The paper's speed at less cost": each examples/gaits/efficient gait over 16 perturbed
    episodes at its full trial length is faster than the paper's gait at the median, and costs less: than the
    paper's gait for the two complexes and the ribbed spine, than the climbed sidewinding Tetraspine gait (run
    beside it) for the Tetraspine, whose paper COT is not reached."""
    gaits = sorted(f"efficient/{p.stem}" for p in (ROOT / "examples" / "gaits" / "efficient").glob("*.json"))
    assert gaits == ["efficient/octahedral-complex", "efficient/ribbed", "efficient/tetrahedral-complex",
                     "efficient/tetraspine"]
    r = subprocess.run([sys.executable, "bench/paper_table.py", "--episodes", "16", "--configs", "bullet", "--gaits",
                        ",".join([*gaits, "climbed/tetraspine"])], cwd=ROOT, capture_output=True, text=True,
                       timeout=1800)
    assert r.returncode == 0, r.stderr[-2000:]
    rows = json.loads(r.stdout.strip().splitlines()[-1])["spines"]
    climbed = rows.pop("climbed/tetraspine")
    assert sorted(rows) == gaits
    for gait, row in rows.items():
        assert row["median_speed_cm_s"] > row["paper_speed_cm_s"], (gait, row)
        assert row["configs"]["bullet"]["failed"] == 0
        if gait != "efficient/tetraspine":
            assert row["median_cot"] < row["paper_cot"], (gait, row)
    assert rows["efficient/tetraspine"]["median_cot"] < climbed["median_cot"]
