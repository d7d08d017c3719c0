"""One search over body and gait: a real search of a spec file with a `search:` block stores every trial as
complete or infeasible with its reason, names the body's constants with their units, exports the best body as
a robot file that re-runs the best trial's distance bit for bit, and resumes with its body search."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import spinefarm
from spinefarm.robot.morphology.registry import load_morphology

ROOT = Path(__file__).resolve().parents[2]
TRIALS = 12
DURATION_S = 0.3
# spacing down to 0.5 % of the file's: segments a few cm apart cannot hold, some sampled bodies must fail
SPEC = textwrap.dedent("""\
    base: tetraspine-ntrt
    name: co-spine
    search:
      segments.spacing_scale: [0.005, 1.2]
      string_materials.outer.stiffness_n_per_m: [700, 1300]
      rod_materials.rod.density_kg_per_cm3: [0.0098, 0.0182]
    """)
BODY = ["body.segments.spacing_scale", "body.string_materials.outer.stiffness_n_per_m",
        "body.rod_materials.rod.density_kg_per_cm3"]


def run(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "spinefarm", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=600)


@pytest.fixture(scope="module")
def codesigned(tmp_path_factory) -> tuple[Path, Path]:
    folder = tmp_path_factory.mktemp("codesign")
    spec = folder / "co.yaml"
    spec.write_text(SPEC)
    out = folder / "co.h5"
    r = run("search", str(spec), "--trials", str(TRIALS), "--workers", "1", "--duration", str(DURATION_S),
            "--engine", "bullet", "--seed", "0", "--api-port", "-1", "--quiet", "--out", str(out))
    assert r.returncode == 0, r.stderr
    return folder, out


def test_every_trial_is_complete_or_infeasible_with_its_reason(codesigned):
    _, out = codesigned
    df = spinefarm.load_run(out)
    assert len(df) == TRIALS and set(df["status"]) <= {"complete", "failed"}
    failed = df[df["status"] == "failed"]
    assert len(failed) >= 1 and all(r.startswith("infeasible: ") for r in failed["reason"])
    assert list(df.columns[df.columns.str.startswith("body.")]) == BODY
    assert [df.attrs["units"][c] for c in BODY] == ["1", "N/m", "kg/cm^3"]
    # 116 NTRT parameters of the 3-segment Tetraspine (docs/morphology-format.md), then the body's 3
    assert len(df.attrs["param_names"] if "param_names" in df.attrs else [c for c in df.columns
               if c.startswith(("cpg_", "coupling_", "body."))]) == 116 + 3
    complete = df[df["status"] == "complete"]
    # each trial ran its own body: the segment mass follows the sampled density (mass = density x volume)
    ratio = complete["mass_kg"] / complete[BODY[2]]
    assert complete["mass_kg"].nunique() == len(complete)
    assert np.allclose(ratio, ratio.iloc[0], rtol=1e-9)
    # each trial names the body it ran, failed ones too: 16 hex digits, one per distinct body
    assert all(len(h) == 16 for h in df["body_hash"]) and df["body_hash"].nunique() == len(df)


def test_the_exported_body_reruns_the_best_distance_bit_for_bit(codesigned):
    folder, out = codesigned
    r = run("export", str(out), "--spec", str(folder / "best.yaml"), "--gait", str(folder / "gait.json"))
    assert r.returncode == 0, r.stderr
    df = spinefarm.load_run(out)
    gait = json.loads((folder / "gait.json").read_text())
    best = df.loc[gait["source"]["trial_id"]]
    assert not any(k.startswith("body.") for k in gait["params"])
    robot = load_morphology(str(folder / "best.yaml"))
    assert robot.spec_hash() == best["body_hash"]  # the very robot the trial ran
    body = robot.structure
    assert body.string_material("outer").stiffness_n_per_m == best[BODY[1]]
    assert body.rod_material("rod").density_kg_per_cm3 == best[BODY[2]]
    r = run("trial", str(folder / "best.yaml"), "--params", str(folder / "gait.json"), "--seed", str(best["seed"]),
            "--duration", str(DURATION_S), "--engine", "bullet", "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["distance_m"] == best["distance_m"]


def test_a_fixed_body_run_refuses_spec_in_one_line(tmp_path):
    out = tmp_path / "plain.h5"
    assert run("search", "sphere:2", "--trials", "3", "--workers", "1", "--api-port", "-1", "--quiet", "--out",
               str(out)).returncode == 0
    r = run("export", str(out), "--spec", str(tmp_path / "x.yaml"))
    assert r.returncode != 0 and "--spec needs a co-designed run" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not (tmp_path / "x.yaml").exists()


def test_a_resumed_codesigned_run_keeps_its_body_search(tmp_path):
    from spinefarm.coordinator.problem import build_run_config
    from spinefarm.coordinator.setup import SearchSettings, new_run, resume_run
    from spinefarm.robot.codesign import BodySearch
    from spinefarm.worker.service.evaluators import build_evaluator

    spec = tmp_path / "co.yaml"
    spec.write_text(SPEC)
    config = build_run_config("co-1", str(spec), duration_s=0.2, seed=3)
    core, storage = new_run(config, SearchSettings(trials=20), tmp_path / "run.h5")
    for tid in range(2):
        assert core.study.ask() == tid
    expected = core.study.sampler.propose(2, storage)
    storage.close()
    spec.unlink()  # the file is gone: the run resumes from what it stored
    core2, storage2 = resume_run(tmp_path / "run.h5")
    try:
        assert core2.run_config.body == config.body and core2.run_config.space_hash == config.space_hash
        assert len(core2.run_config.param_space) == 116 + 3
        got = core2.study.sampler.propose(2, storage2)
        assert np.array_equal(expected.params_unit, got.params_unit)
        build_evaluator(core2.run_config)  # a worker rebuilds the run, its body search included
        # and builds the same robots from it: a spec's key order (node numbering) survives the run file
        values = {f.path: (f.low + f.high) / 2 for f in BodySearch.from_dict(config.body).fields}
        before, after = (BodySearch.from_dict(c.body).body(values) for c in (config, core2.run_config))
        assert before.spec_hash() == after.spec_hash()
        assert before.structure.node_names[:4] == ("s0.right", "s0.left", "s0.top", "s0.front")  # the file's order
    finally:
        storage2.close()


def test_an_enqueued_gait_starts_on_the_files_own_body(tmp_path):
    from spinefarm.cli.run_setup import _with_file_body
    from spinefarm.protocol.errors import MorphologySpecError

    spec = tmp_path / "co.yaml"
    spec.write_text(SPEC)
    gait = (0.25, 0.75)
    got = _with_file_body(str(spec), gait)
    # the file's spacing 1 in [0.005, 1.2]; the paper's k = 1000 N/m and 4.2 / 300 kg/cm^3, mid-range of +-30 %
    assert got[:2] == gait
    assert got[2:] == pytest.approx(((1.0 - 0.005) / 1.195, 0.5, 0.5), abs=1e-12)
    assert _with_file_body("tetraspine", gait) == gait  # a built-in has no search block
    spec.write_text(SPEC.replace("[700, 1300]", "[1100, 1300]"))
    with pytest.raises(MorphologySpecError, match=r"outside its search range; received 1000\.0"):
        _with_file_body(str(spec), gait)


def test_pictures_and_the_player_draw_the_trials_own_body(tmp_path):
    from spinefarm.coordinator.problem import build_run_config
    from spinefarm.robot.codesign import BodySearch
    from spinefarm.worker.tools.motion import simulate_motion

    spec = tmp_path / "co.yaml"
    spec.write_text(SPEC)
    config = build_run_config("co-1", str(spec), duration_s=0.05)
    unit = np.full(len(config.param_space), 0.5)
    unit[-3] = 1.0  # spacing 1.2: the segments 1.2 x 28.575 cm apart along z
    job = {"morphology": config.morphology_spec, "controller": config.controller, "trial_config": config.trial_config,
           "params_unit": unit.tolist(), "seed": 1, "body": config.body}
    motion = simulate_motion(job)
    # by hand: rod masses go with their lengths (five 38.1 cm edges, the 33.0 cm top-front rod); the three rods
    # to the front apex are centred 14.2875 cm forward, so a segment's centre of mass is 6.98 cm ahead of its
    # frame; the frames sit at z = 71.425 - 1.2 * 28.575 * i, so the robot's at 71.425 - 1.2 * 28.575 (i = 1)
    top_front_cm = np.hypot(32.99557 / 2, 28.575)
    ahead_cm = 14.2875 * (2 * 38.1 + top_front_cm) / (5 * 38.1 + top_front_cm)
    assert motion["com_cm"][0][2] == pytest.approx(ahead_cm + 71.425 - 1.2 * 28.575, abs=0.05)
    assert BodySearch.from_dict(config.body).fields[0].path == "segments.spacing_scale"
