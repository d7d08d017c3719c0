"""Replaying NTRT's published gaits: reading .nnw files, the reversed slot order, the command."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from spinefarm.cli.main import main
from spinefarm.protocol.errors import ConfigError
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.spaces import controller_space, param_space
from spinefarm.worker.tools.replay import (
    PUBLISHED_DIR,
    REFERENCES,
    detect_morphology,
    read_nnw,
    read_parameter_set,
    replay,
    unit_params,
)

REF = PUBLISHED_DIR  # NTRT's parameter sets, shipped with the package
FOLDERS = {"tetraspine-ntrt": "TetraSpine", "tetrahedral-complex": "TetrahedralComplex",
           "octahedral-complex": "OctahedralComplex", "ribbed": "Ribbed"}
needs_data = pytest.mark.skipif(not REF.is_dir(), reason="NTRT reference data not present")


def _folder(name: str) -> Path:
    return REF / FOLDERS[name] / "paper-2014-06-07"


def test_read_nnw_keeps_both_values_without_a_trailing_newline(tmp_path: Path):
    f = tmp_path / "x.nnw"
    f.write_text("0.25,0.875")
    assert read_nnw(f) == (0.25, 0.875)
    f.write_text("0.5,1.5")
    with pytest.raises(ConfigError, match=r"x.nnw does not hold two values in \[0, 1\]"):
        read_nnw(f)
    f.write_text("0.5")
    with pytest.raises(ConfigError, match="two values"):
        read_nnw(f)
    f.write_text("a,b")
    with pytest.raises(ConfigError, match="not two comma-separated numbers"):
        read_nnw(f)


def _write_set(folder: Path, n_edges: int, missing: int | None = None) -> list[tuple[float, float]]:
    logs = folder / "logs"
    logs.mkdir(parents=True)
    (logs / "bestParameters-default_node-0.nnw").write_text("0.1,0.2")
    edges = [(round(i / 100, 2), round(1 - i / 100, 2)) for i in range(n_edges)]
    for i, (w, p) in enumerate(edges):
        if i != missing:
            (logs / f"bestParameters-default_edge-{i}.nnw").write_text(f"{w},{p}")
    return edges


def test_edge_file_i_fills_slot_ne_minus_1_minus_i(tmp_path: Path):
    morph = load_morphology("octahedral-complex")
    edges = _write_set(tmp_path / "OctahedralComplex", 26)
    params = read_parameter_set(tmp_path / "OctahedralComplex")
    assert params.node == (0.1, 0.2) and list(params.edges) == edges
    u = unit_params(morph, params)
    assert u.shape == (54,)
    assert tuple(u[:2]) == (0.1, 0.2)
    for slot in range(26):
        assert tuple(u[2 + 2 * slot: 4 + 2 * slot]) == edges[25 - slot]
    names = param_space(morph).names
    assert names[2] == "coupling_r0_0_0_weight" and u[2] == edges[-1][0]  # slot (0,0,0) <- the last file
    physical = param_space(morph).from_unit(u)
    assert physical[3] == pytest.approx(-math.pi + 2 * math.pi * edges[-1][1])


def test_missing_or_wrong_count_of_edge_files_is_an_error(tmp_path: Path):
    _write_set(tmp_path / "a", 26, missing=7)
    with pytest.raises(ConfigError, match=r"missing \[7\]"):
        read_parameter_set(tmp_path / "a")
    _write_set(tmp_path / "b", 25)
    with pytest.raises(ConfigError, match=r"wrong number of NTRT edge files.*expected 26"):
        unit_params(load_morphology("octahedral-complex"), read_parameter_set(tmp_path / "b"))
    with pytest.raises(ConfigError, match="not found"):
        read_parameter_set(tmp_path / "nowhere")


def test_robot_is_detected_from_the_path(tmp_path: Path):
    for name, folder in FOLDERS.items():
        assert detect_morphology(tmp_path / folder / "paper-2014-06-07") == name
    with pytest.raises(ConfigError, match="--morphology"):
        detect_morphology(tmp_path / "Elsewhere")


@needs_data
def test_a_spec_file_given_to_replay_says_how_to_run_ntrt_parameters_on_it(tmp_path: Path, capsys):
    """A spec file has no published parameters: the error says so and names the way that works, which does."""
    spec = tmp_path / "my-octa.yaml"
    assert main(["spec", "octahedral-complex", "--name", "my-octa"]) == 0
    spec.write_text(capsys.readouterr().out)
    assert main(["replay", str(spec)]) == 2
    err = capsys.readouterr().err
    assert "not a file" in err and str(spec) in err and "--morphology FILE.yaml" in err and "trial --run" in err
    assert main(["replay", str(_folder("octahedral-complex")), "--morphology", str(spec), "--duration", "0.05",
                 "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["morphology"] == "my-octa"


@needs_data
@pytest.mark.parametrize(("name", "n_edges", "f", "amp"), [
    ("tetraspine-ntrt", 57, 5.5764, 29.779), ("tetrahedral-complex", 100, 3.78642, 16.3102),
    ("octahedral-complex", 26, 20.8169, 9.458), ("ribbed", 77, 1.98021, 23.9918)])
def test_published_sets_map_to_the_spec_values(name: str, n_edges: int, f: float, amp: float):
    """Spec 8: both node values are read and scaled by the robot's node range."""
    morph = load_morphology(name)
    params = read_parameter_set(_folder(name))
    assert len(params.edges) == n_edges
    physical = param_space(morph).from_unit(unit_params(morph, params))
    assert physical[0] == pytest.approx(f, abs=1e-3)
    assert physical[1] == pytest.approx(amp, abs=1e-3)
    weights = physical[2::2]
    assert 0.4 < weights.mean() < 0.56  # spec 8: edge weights average about 0.45-0.53
    # the phase (second value) of every edge file is used, not only the weight
    phases = physical[3::2]
    files = np.array([p for _, p in params.edges][::-1])
    np.testing.assert_allclose(phases, -math.pi + 2 * math.pi * files)


@needs_data
def test_replay_command_json_short(capsys):
    code = main(["replay", str(_folder("octahedral-complex")), "--duration", "0.3", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0
    assert out["morphology"] == "octahedral-complex" and out["status"] == "complete"
    assert out["n_edge_files"] == 26 and out["node_values"] == [0.693896, 0.315267]
    assert out["ntrt_reference_cm"] == REFERENCES["octahedral-complex"].distance_cm
    assert out["ntrt_distance_cm"] > 0 and out["sim_time_s"] == pytest.approx(0.3)
    assert out["ratio"] == pytest.approx(out["speed_cm_s"] / (98.5485 / 30.0))


@needs_data
def test_replay_text_says_when_it_diverges(monkeypatch, capsys):
    from dataclasses import replace as dc_replace

    import spinefarm.worker.tools.replay as rp

    real = rp.replay(_folder("octahedral-complex"), duration_s=0.05)
    failed = dc_replace(real, result=dc_replace(real.result, status=type(real.result.status)("failed"),
                                                reason="diverged: non-finite pose at t=0.040 s"))
    monkeypatch.setattr(rp, "replay", lambda *a, **k: failed)
    assert main(["replay", str(_folder("octahedral-complex"))]) == 1
    text = capsys.readouterr().out
    assert "DIVERGED: diverged: non-finite pose" in text and "n/a (diverged)" in text
    assert main(["replay", str(_folder("octahedral-complex")), "--json"]) == 1
    out = json.loads(capsys.readouterr().out)
    assert out["status"] == "diverged" and out["ratio"] is None


@needs_data
@pytest.mark.parametrize(("name", "low", "high"), [("octahedral-complex", 0.8, 1.3),
                                                   ("tetrahedral-complex", 0.4, 2.0)])
def test_full_replay_lands_near_ntrt(name: str, low: float, high: float):
    """30 s at 1 ms with the 2014 motor. Octahedral: measured 1.15 x NTRT; the tetrahedral complex is
    chaotic (spec 0a.5), so only the order of magnitude is asserted."""
    report = replay(_folder(name))
    assert report.result.ok, report.result.reason
    assert low < report.ratio < high, report.ratio


@needs_data
@pytest.mark.parametrize("name", ["ribbed", "tetraspine-ntrt"])
def test_full_replay_without_a_reference_completes(name: str):
    report = replay(_folder(name))
    assert report.reference is None and report.ratio is None
    assert report.result.ok, report.result.reason
    assert report.result.ntrt_distance_cm > 5.0


@needs_data
def test_replay_spread_over_jittered_start_poses(capsys):
    assert main(["replay", str(_folder("tetrahedral-complex")), "--duration", "0.2", "--seeds", "2", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    spread = out["spread"]
    assert spread["n"] == 2 and len(spread["ntrt_distance_cm"]) == 2 and spread["jitter_cm"] == 1e-6
    assert spread["min_cm"] <= spread["median_cm"] <= spread["max_cm"]
    assert main(["replay", str(_folder("tetrahedral-complex")), "--seeds", "-1"]) == 2


def test_replay_writes_the_set_as_a_gait_file_that_trial_runs_alike(tmp_path: Path, capsys):
    gait = tmp_path / "gaits" / "ntrt-octahedral.json"
    assert main(["replay", "octahedral-complex", "--duration", "0.3", "--json", "--gait", str(gait)]) == 0
    replayed = json.loads(capsys.readouterr().out)
    g = json.loads(gait.read_text())
    assert g["morphology"] == "octahedral-complex" and g["controller"] == "ntrt"
    space = controller_space(load_morphology("octahedral-complex"), "ntrt").param_space
    assert list(g["params"]) == space.names
    published = unit_params(load_morphology("octahedral-complex"), read_parameter_set(_folder("octahedral-complex")))
    assert np.allclose(space.to_unit(space.from_named(g["params"])), published, rtol=0, atol=1e-12)
    # under the replay's settings the file runs the replay again
    assert main(["trial", "octahedral-complex", "--params", str(gait), "--duration", "0.3", "--dt", "0.001",
                 "--motor-model", "ntrt2014", "--engine-option", "friction_anchor=false", "--json"]) == 0
    again = json.loads(capsys.readouterr().out)
    assert again["ntrt_distance_cm"] == pytest.approx(replayed["ntrt_distance_cm"], rel=1e-9)
    assert main(["replay", "octahedral-complex", "--gait", str(tmp_path / "gait.txt")]) == 2
    assert "--gait has the wrong extension" in capsys.readouterr().err
