"""The YAML morphology format: good files build, bad files fail naming the line, field and expectation."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest

from spinefarm.cli.main import main
from spinefarm.protocol.errors import MorphologySpecError, UnknownMorphologyError
from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.morphology.registry import builtin_names, builtin_path, load_morphology
from spinefarm.robot.morphology.specfile import SPEC_DIR, load_spec_file, parse_spec
from spinefarm.robot.spaces import param_space

GOOD = textwrap.dedent("""\
    name: bar-chain
    description: three crossed bars per segment, {segments} segments
    segments:
      count: 4
      nodes:
        a: [-5, 0, 0]
        b: [5, 0, 0]
        c: [0, 0, -5]
        d: [0, 0, 5]
        up: [0, 6, 0]
      rods:
        - [a, b, bar]
        - [c, d, bar]
        - [a, up, bar]
        - [b, up, bar]
      transforms:
        - rotate: {axis: [0, 1, 0], degrees: 90}
          when: odd
        - translate: [0, 3, "-12 * i"]
    joints:
      - {tag: muscle, strings: [[a, a], [b, b], [up, up]]}
      - {tag: tendon, strings: [[c, d]]}
    rod_materials:
      bar: {radius_cm: 0.5, density_kg_per_cm3: 0.014, friction: 0.5}
    string_materials:
      muscle: {stiffness_n_per_m: 800}
      tendon: {stiffness_n_per_m: 300, damping_n_s_per_m: 3}
    control:
      cpg_tags: [muscle]
      impedance:
        muscle: {position_gain_n_per_m: 500, velocity_gain_n_s_per_m: 50}
      cpg_update_period_s: 0.01
    duration_s: 10
""")


def test_good_file_builds_what_it_says(tmp_path: Path):
    path = tmp_path / "chain.yaml"
    path.write_text(GOOD)
    morph = load_spec_file(path)
    s = morph.structure
    assert morph.name == "bar-chain" and s.n_segments == 4
    assert len(s.nodes) == 20 and len(s.rods) == 16
    assert morph.description == "three crossed bars per segment, 4 segments"
    # passive (non-CPG) strings first, then CPG strings joint by joint
    assert [t.tag for t in s.strings] == ["tendon"] * 3 + ["muscle"] * 9
    assert s.node_names[s.strings[3].a] == "s0.a" and s.node_names[s.strings[3].b] == "s1.a"
    nodes = s.node_array()
    np.testing.assert_allclose(nodes[0], [-5, 3, 0])            # segment 0, node a
    np.testing.assert_allclose(nodes[5], [0, 3, -12 + 5], atol=1e-12)  # segment 1 turned 90 deg about +Y
    assert morph.scored_segment == 2 and morph.duration_s == 10.0
    assert morph.control.gains("muscle").position_gain_n_per_m == 500
    assert morph.control.gains("tendon") is None
    assert s.string_material("tendon").damping_n_s_per_m == 3
    assert len(param_space(morph)) == 2 + 2 * (3 * 3 * 4 // 2 - 3)


def test_spec_file_runs_through_the_registry_and_trial_command(tmp_path: Path, capsys):
    path = tmp_path / "chain.yaml"
    path.write_text(GOOD)
    assert load_morphology(str(path)).spec_hash() == load_spec_file(path).spec_hash()
    assert main(["trial", str(path), "--random-seed", "2", "--duration", "0.2", "--json"]) == 0
    assert '"morphology": "bar-chain"' in capsys.readouterr().out


def builtin_spec(stem: str, *, segments: int | None = None, name: str | None = None) -> Morphology:
    """A built-in's spec file loaded at another segment count or under another name."""
    return load_spec_file(builtin_path(stem), segments=segments, name=name)


def test_a_spec_starts_from_a_base_and_overrides_what_it_names(tmp_path: Path):
    ntrt = load_morphology("tetraspine-ntrt")
    assert ntrt.spec_hash() == builtin_spec("tetraspine", segments=3, name="tetraspine-ntrt").spec_hash()
    stiff = tmp_path / "stiff.yaml"
    stiff.write_text("base: tetraspine\nname: stiff\nstring_materials:\n  outer: {stiffness_n_per_m: 2000}\n")
    morph = load_spec_file(stiff)
    mats = dict(morph.structure.string_materials)
    assert mats["outer"].stiffness_n_per_m == 2000 and mats["inner"].stiffness_n_per_m == 1000
    assert morph.structure.n_segments == 12 and morph.name == "stiff"
    (tmp_path / "loop.yaml").write_text("base: loop.yaml\nname: loop\n")
    with pytest.raises(MorphologySpecError, match="cycle"):
        load_spec_file(tmp_path / "loop.yaml")
    (tmp_path / "orphan.yaml").write_text("base: no-such-robot\nname: orphan\n")
    with pytest.raises(MorphologySpecError, match=r"line 1, field base: no such spec"):
        load_spec_file(tmp_path / "orphan.yaml")


def test_every_builtin_is_a_spec_file():
    assert builtin_names() == sorted(p.stem for p in SPEC_DIR.glob("*.yaml"))
    for name in builtin_names():
        assert load_morphology(name).name == name
        assert load_morphology(name).spec_hash() == load_spec_file(SPEC_DIR / f"{name}.yaml").spec_hash()



def test_octahedral_segments_follow_the_alternating_rotations():
    """Spec 6.3 lists segment 0 and segment 1 node coordinates explicitly."""
    nodes = load_morphology("octahedral-complex").structure.node_array()
    r, h = 7.07107, 5.0
    seg0 = [(0, 15, 87.5), (-r, 15 + r, 87.5), (r, 15 - r, 87.5), (-h, 10, 87.5 + r), (h, 20, 87.5 - r),
            (h, 20, 87.5 + r), (-h, 10, 87.5 - r)]
    seg1 = [(0, 15, 75), (-h, 20, 75 + r), (h, 10, 75 - r), (h, 10, 75 + r), (-h, 20, 75 - r), (r, 15 + r, 75),
            (-r, 15 - r, 75)]
    np.testing.assert_allclose(nodes[:7], seg0, atol=1e-5)
    np.testing.assert_allclose(nodes[7:14], seg1, atol=1e-5)
    np.testing.assert_allclose(nodes[14:21], np.array(seg0) - [0, 0, 25], atol=1e-5)


def test_ribbed_rib_nodes():
    s = load_morphology("ribbed").structure
    named = dict(zip(s.node_names, s.node_array(), strict=True))
    np.testing.assert_allclose(named["s0.centre"], (0, 12, 32.1), atol=1e-12)
    np.testing.assert_allclose(named["s0.r1_3"], (-2.72394, 11.26403, 32.1), atol=1e-5)
    np.testing.assert_allclose(named["s0.r1_5"], (-4.24264, 10.52843, 32.1), atol=1e-5)
    np.testing.assert_allclose(named["s0.r1_12"], (-5.70634, 6.46393, 32.1), atol=1e-5)
    np.testing.assert_allclose(named["s0.r2_12"], (5.70634, 6.46393, 32.1), atol=1e-5)
    np.testing.assert_allclose(named["s1.centre"], (0, 12, 28.2), atol=1e-12)
    assert len([r for r in s.rods if s.node_segment[r.a] == 0]) == 33


def _bad(old: str, new: str) -> str:
    assert old in GOOD, old
    return GOOD.replace(old, new, 1)


def _line_of(text: str, fragment: str) -> int:
    return next(i for i, line in enumerate(text.splitlines(), 1) if fragment in line)


@pytest.mark.parametrize(("old", "new", "line_fragment", "words"), [
    ("- [a, up, bar]", "- [a, top, bar]", "[a, top, bar]", ["segments.rods[2]", "unknown node", "'top'"]),
    ("- [c, d, bar]", "- [c, c, bar]", "[c, c, bar]", ["segments.rods[1]", "rod of zero length", "c -> c"]),
    ("{tag: tendon, strings: [[c, d]]}", "{tag: tendon, span: 0, strings: [[c, d]]}", "tag: tendon",
     ["joints[1].span", "string joining a body to itself", "span >= 1"]),
    ("- [b, up, bar]", "- [b, up, strut]", "[b, up, strut]", ["segments.rods[3].tag", "no rod config", "'strut'"]),
    ("{tag: tendon, strings: [[c, d]]}", "{tag: cable, strings: [[c, d]]}", "tag: cable",
     ["joints[1].tag", "no string config", "'cable'"]),
    ("    muscle: {position_gain_n_per_m: 500,", "    tendon: {position_gain_n_per_m: 500,", "cpg_tags",
     ["control.impedance", "missing config for a CPG tag", "'muscle'"]),
    ("{tag: muscle, strings: [[a, a], [b, b], [up, up]]}", "{tag: muscle, strings: [[a, a], [b, bb]]}",
     "tag: muscle, strings", ["joints[0].strings[1]", "unknown node", "'bb'"]),
    ("muscle: {stiffness_n_per_m: 800}", "muscle: {stiffness_n_per_m: 800, stifness: 3}", "stifness",
     ["string_materials.muscle.stifness", "unknown key", "stiffness_n_per_m"]),
    ("muscle: {stiffness_n_per_m: 800}", "muscle: {stiffness_n_per_m: -800}", "muscle: {stiffness_n_per_m: -800}",
     ["string_materials.muscle", "stiffness_n_per_m out of range", "-800"]),
    ('- translate: [0, 3, "-12 * i"]', '- translate: [0, 3, "-12 * j"]', "translate:",
     ["segments.transforms[1].translate[2]", "unknown name 'j'"]),
    ('- translate: [0, 3, "-12 * i"]', '- translate: [0, 3, "__import__(\'os\')"]', "translate:",
     ["segments.transforms[1].translate[2]", "Call is not allowed"]),
    ("      when: odd", "      when: sometimes", "when: sometimes", ["when", "unknown selector", "'sometimes'"]),
    ("duration_s: 10", "duration: 10", "duration: 10", ["(document).duration", "unknown key"]),
    ("  count: 4", "  count: 1", "count: 1", ["segments.count", "not an integer >= 2"]),
])
def test_bad_files_name_line_field_and_expectation(old, new, line_fragment, words, tmp_path: Path):
    text = _bad(old, new)
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(MorphologySpecError) as info:
        load_spec_file(path)
    msg = str(info.value)
    assert f"{path}, line {_line_of(text, line_fragment)}" in msg, msg
    for w in words:
        assert w in msg, msg
    assert "expected" in msg


def test_yaml_syntax_and_empty_files_are_reported(tmp_path: Path):
    with pytest.raises(MorphologySpecError, match=r"line 4.*not valid YAML"):
        parse_spec("name: x\nsegments:\n  count: [4\n")
    with pytest.raises(MorphologySpecError, match="empty"):
        parse_spec("")
    with pytest.raises(MorphologySpecError, match="duplicate key"):
        parse_spec("name: x\nname: y\n")
    with pytest.raises(MorphologySpecError, match="cannot read"):
        load_spec_file(tmp_path / "missing.yaml")
    with pytest.raises(UnknownMorphologyError):
        load_morphology(str(tmp_path / "missing.yaml"))


def test_cli_reports_a_bad_file_as_an_error(tmp_path: Path, capsys):
    path = tmp_path / "bad.yaml"
    path.write_text(_bad("- [a, up, bar]", "- [a, top, bar]"))
    assert main(["trial", str(path), "--duration", "0.1"]) == 2
    err = capsys.readouterr().err
    assert "unknown node" in err and f"line {_line_of(path.read_text(), '[a, top, bar]')}" in err


def test_builders_take_a_segment_count():
    tetra4 = builtin_spec("tetrahedral-complex", segments=4)
    assert tetra4.scored_segment == 2 and tetra4.structure.n_segments == 4
    assert len(builtin_spec("octahedral-complex", segments=5).structure.strings) == 4 * 8
    assert builtin_spec("ribbed", segments=3, name="ribbed-3").name == "ribbed-3"
    with pytest.raises(MorphologySpecError, match=r"segments\.count"):
        builtin_spec("tetrahedral-complex", segments=1)
