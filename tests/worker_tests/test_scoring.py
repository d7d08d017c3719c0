"""Scoring (worker.trial.scoring, worker.trial.episode.score) against figures worked by hand: the planar distance in the
ground plane (x, z; y is up), the mass-weighted centre, COT = W / (m g d) with g = 9.81 m/s^2, work converted
from kg cm^2/s^2 to J (x 1e-4), and a settle phase's work never counted as locomotion's."""

from __future__ import annotations

import math

import numpy as np
import pytest

from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.worker.trial import scoring
from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, simulate


def test_planar_distance_ignores_height():
    # (3, 4) in the ground plane is 5 cm, whatever the height does
    assert scoring.planar_distance_cm(np.array([1.0, 7.0, 2.0]), np.array([4.0, -20.0, 6.0])) == 5.0


def test_centre_of_mass_weighs_by_mass():
    # 1 kg at x=0 and 3 kg at x=4: centre at x=3; the 4th..7th columns (orientation) are not positions
    poses = np.array([[0.0, 2.0, 0.0, 9, 9, 9, 9], [4.0, 2.0, 8.0, 9, 9, 9, 9]])
    assert scoring.robot_com_cm(poses, np.array([1.0, 3.0])).tolist() == [3.0, 2.0, 6.0]


def test_cost_of_transport_by_hand():
    # 19.62 J moving 2 kg by 0.5 m: 19.62 / (2 * 9.81 * 0.5) = 2
    assert scoring.cost_of_transport(19.62, 2.0, 0.5) == pytest.approx(2.0, rel=1e-12)
    assert scoring.cost_of_transport(1.0, 2.0, 0.0) == math.inf
    assert scoring.cost_of_transport(1.0, 2.0, -0.1) == math.inf
    assert scoring.cost_of_transport(1.0, 2.0, math.nan) == math.inf
    assert scoring.WORK_J_PER_INTERNAL == 1e-4  # 1 kg cm^2/s^2 = 1e-4 kg m^2/s^2


def test_rms_path_error_by_hand():
    # a path 3 cm off in x then 4 cm in z at the reference's times: sqrt((9 + 16) / 2)
    t = np.array([0.0, 1.0])
    ref = np.zeros((2, 3))
    path = np.array([[3.0, 0.0, 0.0], [0.0, 0.0, 4.0]])
    assert scoring.rms_path_error_cm(path, t, ref, t) == pytest.approx(math.sqrt(12.5), rel=1e-12)
    # the path interpolated onto the reference's middle time: (1.5, 0, 2) -> 2.5 cm
    t3 = np.array([0.0, 0.5, 1.0])
    assert scoring.rms_path_error_cm(path, t, np.zeros((3, 3)), t3) == pytest.approx(
        math.sqrt((9 + 2.5**2 + 16) / 3), rel=1e-12)
    # only the time both cover counts: a reference running past the path's end is cut there
    assert scoring.rms_path_error_cm(path, t, np.zeros((3, 3)), np.array([0.0, 1.0, 2.0])) == pytest.approx(
        math.sqrt(12.5), rel=1e-12)
    assert math.isnan(scoring.rms_path_error_cm(path[:1], t[:1], ref, t))
    # against a reference that is not at the origin: differences (2, 0, 0) and (0, 0, 3)
    off = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    assert scoring.rms_path_error_cm(path, t, off, t) == pytest.approx(math.sqrt(6.5), rel=1e-12)


def test_cot_with_a_settle_phase_counts_only_locomotion():
    """The settle phase's work is not the gait's: a trial that settles 0.5 s then moves for 0.01 s did almost
    no work (under a tenth of what the settle took; counted in, COT rose 18 % on a normal trial). COT is
    W / (m g d) of the figures the trial reports."""
    morph = load_morphology("tetraspine-ntrt")
    u = random_unit_params(morph, 3)
    long = simulate(morph, u, TrialConfig(duration_s=0.5, settle_s=0.5, engine="mujoco"), 3).result
    short = simulate(morph, u, TrialConfig(duration_s=0.01, settle_s=0.5, engine="mujoco"), 3).result
    assert long.extras["settle_s"] == 0.5 and long.sim_time_s == pytest.approx(0.5)
    assert long.work_j > 0
    assert short.work_j < 0.1 * long.work_j, (short.work_j, long.work_j)
    assert long.cot == pytest.approx(long.work_j / (long.mass_kg * 9.81 * long.distance_m), rel=1e-12)
