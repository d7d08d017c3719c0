"""The `search:` block of a spec file: its fields build the bodies they name, and bad blocks fail in one line
naming the field and the line."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from spinefarm.cli.main import main
from spinefarm.protocol.errors import MorphologySpecError
from spinefarm.robot.morphology.bodycheck import _segment_distances, crossing_rods, short_strings
from spinefarm.robot.morphology.specfile import SPEC_DIR, from_document, load_search, parse_spec, spec_document
from spinefarm.robot.morphology.specsearch import with_body

ROOT = Path(__file__).resolve().parents[2]
TETRA = (SPEC_DIR / "tetraspine.yaml").read_text()
TETRA_LINES = TETRA.count("\n")
EDGE_CM = 38.1  # Tetraspine's rod edge; segments 0.75 edge = 28.575 cm apart along z (ntrt-spec 6.1)


def with_block(*lines: str) -> str:
    return TETRA + "search:\n" + "".join(f"  {line}\n" for line in lines)


def fails(text: str) -> str:
    with pytest.raises(MorphologySpecError) as exc:
        parse_spec(text, "mine.yaml")
    msg = str(exc.value)
    assert "\n" not in msg
    return msg


def rod_lengths(text: str) -> np.ndarray:
    s = parse_spec(text).structure
    p = s.node_array()
    return np.array([np.linalg.norm(p[r.a] - p[r.b]) for r in s.rods])


def test_rod_length_scale_stretches_every_rod():
    scaled = TETRA.replace("count: 12", "count: 12\n  rod_length_scale: 1.3")
    lengths = rod_lengths(scaled)
    # five edges of 38.1 cm; top to front spans half the triangle's height up and 28.575 cm forward
    top_front_cm = np.hypot(32.99557 / 2, 28.575)
    per_segment = [EDGE_CM] * 5 + [top_front_cm]
    assert np.allclose(lengths, 1.3 * np.array(per_segment * 12), rtol=1e-6)


def test_spacing_scale_moves_segments_apart_along_the_spine():
    base = parse_spec(TETRA).structure.node_array()
    spaced = parse_spec(TETRA.replace("count: 12", "count: 12\n  spacing_scale: 1.5")).structure.node_array()
    per = 4
    for i in (0, 1, 5, 11):
        shift = spaced[i * per:(i + 1) * per] - base[i * per:(i + 1) * per]
        # segment i sits i * 28.575 cm behind segment 0; half as far again at 1.5
        assert np.allclose(shift, [0.0, 0.0, -0.5 * i * 0.75 * EDGE_CM], atol=1e-9)


def test_a_search_block_leaves_the_robot_and_its_hash_alone():
    text = with_block("segments.rod_length_scale: [0.7, 1.3]", "string_materials.outer.stiffness_n_per_m: [700, 1300]")
    assert parse_spec(text).spec_hash() == parse_spec(TETRA).spec_hash()


def test_with_body_writes_the_values_into_the_robot():
    spec, doc = spec_document(with_block("string_materials.outer.stiffness_n_per_m: [700, 1300]"))
    body = from_document(spec, with_body(doc, {"string_materials.outer.stiffness_n_per_m": 1234.0,
                                               "rod_materials.rod.density_kg_per_cm3": 0.01,
                                               "segments.rod_length_scale": 0.8}))
    s = body.structure
    assert s.string_material("outer").stiffness_n_per_m == 1234.0
    assert s.string_material("inner").stiffness_n_per_m == 1000.0  # the file's default, untouched
    assert s.rod_material("rod").density_kg_per_cm3 == 0.01
    p = s.node_array()
    assert np.linalg.norm(p[0] - p[1]) == pytest.approx(0.8 * EDGE_CM, rel=1e-5)


def test_unknown_field_names_field_and_line():
    msg = fails(with_block("segments.rod_length_scale: [0.7, 1.3]", "string_materials.outer.stifness_n_per_m: [1, 2]"))
    assert f"line {TETRA_LINES + 3}" in msg and "field search.string_materials.outer.stifness_n_per_m" in msg
    assert "unknown field" in msg
    msg = fails(with_block("string_materials.tendon.stiffness_n_per_m: [700, 1300]"))  # no such tag
    assert "unknown field" in msg and "string_materials.inner.stiffness_n_per_m" in msg


def test_the_segment_count_is_not_searchable():
    msg = fails(with_block("segments.count: [4, 12]"))
    assert "the segment count is fixed" in msg and f"line {TETRA_LINES + 2}" in msg


@pytest.mark.parametrize(("line", "received", "expected"), [
    ("string_materials.outer.stiffness_n_per_m: [-5, 1300]", "received -5.0", "(0, inf)"),
    ("string_materials.inner.pretension_n: [-1, 3]", "received -1.0", "[0, inf)"),
    ("segments.rod_length_scale: [0.5, 130]", "received 130.0", "(0, 100]"),
    ("rod_materials.rod.density_kg_per_cm3: [0, 0.02]", "received 0.0", "(0, inf)"),
])
def test_a_bound_outside_the_fields_valid_values(line, received, expected):
    msg = fails(with_block(line))
    assert "bound outside the field's valid values" in msg and received in msg and expected in msg
    assert f"line {TETRA_LINES + 2}" in msg


def test_malformed_and_empty_ranges():
    assert "empty range" in fails(with_block("string_materials.outer.damping_n_s_per_m: [3, 2]"))
    assert "not a [low, high] pair" in fails(with_block("string_materials.outer.damping_n_s_per_m: 3"))
    assert "no fields to search" in fails(TETRA + "search: {}\n")


def test_a_range_that_admits_no_valid_body():
    # 500 N on a 1000 N/m string is 50 cm of stretch: more than any Tetraspine string's 28.6 cm start length
    msg = fails(with_block("segments.rod_length_scale: [0.9, 1.1]", "string_materials.outer.pretension_n: [500, 900]"))
    assert "field search.string_materials.outer.pretension_n" in msg and f"line {TETRA_LINES + 3}" in msg
    assert "admits no valid body" in msg and "cannot hold their pretension" in msg
    # segments 0.3 cm apart put a rod of one through the next one's (radii 0.5 + 0.5 cm)
    msg = fails(with_block("segments.spacing_scale: [0.005, 0.01]"))
    assert "admits no valid body" in msg and "rods through each other" in msg
    # a range with one good end passes, whichever end it is
    parse_spec(with_block("string_materials.outer.pretension_n: [10, 900]"))
    parse_spec(with_block("segments.spacing_scale: [0.005, 1.0]"))


def test_segment_distances_by_hand():
    p0 = np.array([[0.0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]])
    p1 = np.array([[1.0, 0, 0], [1, 0, 0], [1, 0, 0], [1, 0, 0]])
    q0 = np.array([[0.5, 1, -1], [2, 1, 0], [3, 0, 0], [0.5, -2, 0]])
    q1 = np.array([[0.5, 1, 1], [3, 1, 0], [4, 4, 0], [0.5, 2, 0]])
    # crossing above, parallel and past the end, end to end, straight through
    assert _segment_distances(p0, p1, q0, q1) == pytest.approx([1.0, np.sqrt(2.0), 2.0, 0.0])


def test_the_built_ins_pass_the_static_checks():
    from spinefarm.robot.morphology.registry import builtin_names, load_morphology

    for name in builtin_names():
        s = load_morphology(name).structure
        assert crossing_rods(s) is None and short_strings(s) is None, name


def test_spec_search_writes_a_block_check_accepts(tmp_path: Path):
    r = subprocess.run([sys.executable, "-m", "spinefarm", "spec", "tetraspine", "--search"], cwd=ROOT,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    path = tmp_path / "mine.yaml"
    path.write_text(r.stdout)
    found = {f.path: (f.low, f.high, f.unit) for f in load_search(path)}
    # +-30 % of the paper's k = 1000 N/m and of the rods' 4.2 / 300 kg/cm^3
    assert found["string_materials.outer.stiffness_n_per_m"] == (700.0, 1300.0, "N/m")
    assert found["string_materials.inner.stiffness_n_per_m"] == (700.0, 1300.0, "N/m")
    assert found["segments.rod_length_scale"] == (0.7, 1.3, "1")
    low, high, unit = found["rod_materials.rod.density_kg_per_cm3"]
    assert (low, high) == pytest.approx((0.7 * 0.014, 1.3 * 0.014)) and unit == "kg/cm^3"


def test_check_refuses_a_bad_block_in_one_line(tmp_path: Path, capsys):
    path = tmp_path / "bad.yaml"
    path.write_text(with_block("string_materials.outer.stiffness_n_per_m: [700, 1300]",
                               "string_materials.outer.motor_speed_cm_s: [-1, 30]"))
    assert main(["check", str(path)]) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"line {TETRA_LINES + 3}" in err
    assert "search.string_materials.outer.motor_speed_cm_s" in err and "received -1.0" in err
