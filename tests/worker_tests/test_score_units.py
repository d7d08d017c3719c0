"""A trial's figures in their units from poses by hand: 1 cm = 0.01 m, COT = W / (m g d) with g = 9.81 m/s²,
work in kg cm²/s² = 1e-4 J (docs/model.md)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from spinefarm.worker.trial.episode import EpisodeEnd, score


def test_a_trial_scored_from_poses_by_hand() -> None:
    masses = np.array([1.0, 3.0])  # 4 kg
    build = np.zeros((2, 7))
    build[:, 3] = 1.0
    end = build.copy()
    end[:, :3] = [[300.0, 5.0, 400.0], [300.0, 9.0, 400.0]]  # both segments 3 m along x, 4 m along z: 5 m
    end[0, 0] = 340.0   # segment 0 (scored) 3.4 m along x: sqrt(340² + 400²) cm; the COM moves 10 cm more in x
    measured = EpisodeEnd(end_poses=end, steps_done=2000, dt_s=0.005, work_internal=2.5e5, reason="")
    r = score(SimpleNamespace(scored_segment=0), masses, build, measured, seed=7, wall_time_s=1.0, extras={})
    com_cm = np.hypot(310.0, 400.0)  # (340 + 3 x 300) / 4 = 310 cm
    assert r.distance_m == pytest.approx(com_cm / 100.0, rel=1e-12)
    assert r.ntrt_distance_cm == pytest.approx(np.hypot(340.0, 400.0), rel=1e-12)
    assert r.sim_time_s == pytest.approx(10.0, rel=1e-12)
    assert r.speed_cm_s == pytest.approx(com_cm / 10.0, rel=1e-12)
    assert r.work_j == pytest.approx(25.0, rel=1e-12)  # 2.5e5 kg cm²/s² = 25 J
    assert r.cot == pytest.approx(25.0 / (4.0 * 9.81 * com_cm / 100.0), rel=1e-12)
    assert r.ok and r.mass_kg == 4.0 and r.seed == 7
