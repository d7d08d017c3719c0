"""The model of NTRT's current code against NTRT's own recorded run (an excerpt in data/ntrt-recordings): the
expectations are NTRT's recorded numbers, not our code's."""

from __future__ import annotations

import gzip
import re
from pathlib import Path

import numpy as np
import pytest

from spinefarm.robot.bodies import build_bodies
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.tools.replay import detect_morphology, ntrt_motor, read_parameter_set, recorded_run, unit_params
from spinefarm.worker.trial.simulation import simulate

RECORDINGS = Path(__file__).parent / "data" / "ntrt-recordings"
RUN = RECORDINGS / "TetraSpine" / "random-00"
TC_RUN = RECORDINGS / "TetrahedralComplex" / "random-00"
NTRT_NEWTON = 100.0  # NTRT's force unit, kg cm/s^2
GROUND_SHIFT_CM = np.array([0.0, 1.0, 0.0])  # NTRT's ground top is at 1.5 cm, ours at 0.5 cm


def recording(run: Path = RUN) -> dict[str, np.ndarray]:
    with gzip.open(run / "trajectory.csv.gz", "rt") as f:
        names = f.readline().strip().split(",")
        rows = np.loadtxt(f, delimiter=",")
    col = {n: rows[:, i] for i, n in enumerate(names)}
    n_str = sum(n.endswith("_len") for n in names)
    n_seg = sum(n.endswith("_qw") for n in names)
    return {"time_s": col["time_s"],
            "pos_cm": np.stack([np.stack([col[f"seg{s}_{a}"] for a in "xyz"], axis=1) for s in range(n_seg)], axis=1),
            **{k: np.stack([col[f"m{i}_{k}"] for i in range(n_str)], axis=1) for k in ("len", "rest", "tension")}}


def meta() -> tuple[list[float], list[float]]:
    text = (RUN / "model-meta.txt").read_text()
    return ([float(m) for m in re.findall(r"mass=([\d.eE+-]+)", text)],
            [float(m) for m in re.findall(r"start_length=([\d.eE+-]+)", text)])


def ours(duration_s: float, name: str = "tetraspine-ntrt2026", run: Path = RUN
         ) -> tuple[dict[str, np.ndarray], float]:
    morph = load_morphology(name)
    u = unit_params(morph, read_parameter_set(run))
    cfg = TrialConfig(duration_s=duration_s, dt_s=0.001, motor_model=ntrt_motor(morph), controller="ntrt",
                      engine_options={"friction_anchor": False}, record_every_s=0.01)
    out = simulate(morph, u, cfg, 0)
    a = out.trajectory.arrays()
    return a, out.result.ntrt_distance_cm


def test_a_recording_folder_replays_on_the_model_of_ntrts_current_code():
    assert detect_morphology(RUN) == "tetraspine-ntrt2026"
    assert ntrt_motor(load_morphology("tetraspine-ntrt2026")) == "ntrt2026"
    assert ntrt_motor(load_morphology("tetraspine-ntrt")) == "ntrt2014"
    ref = recorded_run(RUN)
    assert ref is not None and ref.distance_cm == 3.22967 and ref.duration_s == 10.0


def test_the_build_and_the_start_are_ntrts():
    """Masses, start lengths, start pose, rest lengths and tensions at t = 0 as NTRT recorded them; after ten
    steps the motor has moved each inner string's rest length by exactly 10 V dt, as NTRT's."""
    masses, starts = meta()
    morph = load_morphology("tetraspine-ntrt2026")
    assert np.allclose([b.mass_kg for b in build_bodies(morph.structure)], masses, rtol=1e-6, atol=0)
    rec = recording()
    a, _ = ours(0.02)
    assert np.allclose(a["length_cm"][0], starts, rtol=1e-9, atol=0)
    assert np.allclose(a["length_cm"][0], rec["len"][0], rtol=1e-6, atol=0)
    assert np.allclose(a["rest_length_cm"][0], rec["rest"][0], rtol=1e-6, atol=0)
    assert np.allclose(a["tension_n"][0] * NTRT_NEWTON, rec["tension"][0], atol=1e-9)
    assert np.allclose(a["poses"][0, :3, :3] + GROUND_SHIFT_CM, rec["pos_cm"][0], atol=1e-5)
    inner = [3, 4, 9, 10]  # reeling in at V = 7 cm/s from the first step (NTRT: start - 0.07 at t = 0.01)
    assert np.allclose(rec["rest"][1, inner], rec["rest"][0, inner] - 0.07, atol=1e-6)
    assert np.allclose(a["rest_length_cm"][1, inner], rec["rest"][1, inner], atol=1e-6)


def test_the_first_half_second_follows_ntrt():
    """Every string's length within 0.15 cm of NTRT's at every recorded row of the first 0.5 s (the 2014 model
    of the same robot is 6 cm off by then), and the scored segment's horizontal displacement within 1 cm of
    NTRT's 2.18 cm (2014 model: 6.5 cm). The gap left is the slow forward drift of docs/replay.md."""
    rec = recording()
    a, dist_cm = ours(0.5)
    n = len(a["time_s"])
    assert n == 51 and np.allclose(a["time_s"], rec["time_s"][:n])
    assert np.abs(a["length_cm"] - rec["len"][:n]).max() < 0.15
    ntrt_cm = float(np.hypot(*(rec["pos_cm"][50, 1] - rec["pos_cm"][0, 1])[[0, 2]]))
    assert ntrt_cm == pytest.approx(2.1787, abs=1e-3)
    assert abs(dist_cm - ntrt_cm) < 1.0


def test_the_tetrahedral_complex_follows_ntrts_kinematic_motors_exactly_while_it_falls():
    """NTRT's current tetrahedral complex winds its strings with kinematic motors under a PD on tension, the
    impedance law reading the spool's speed: over its first 0.09 s (falling to the ground) every rest length
    moves by up to 0.22 cm, and ours follow NTRT's to its printed digits (8 significant)."""
    assert detect_morphology(TC_RUN) == "tetrahedral-complex-ntrt2026"
    rec = recording(TC_RUN)
    a, _ = ours(0.1, "tetrahedral-complex-ntrt2026", TC_RUN)
    n = len(rec["time_s"])
    assert n == 11 and len(a["time_s"]) == n
    assert np.abs(rec["rest"][4] - rec["rest"][0]).max() == pytest.approx(0.2230, abs=1e-4)  # they do move
    falling = slice(0, 10)  # rows 0 ... 0.09 s
    assert np.abs(a["rest_length_cm"][falling] - rec["rest"][falling]).max() < 2e-6
    assert np.abs(a["length_cm"][falling] - rec["len"][falling]).max() < 1e-3
    assert np.abs(a["tension_n"][falling] * NTRT_NEWTON - rec["tension"][falling]).max() < 0.1
