"""A robust trial of one episode (the first rung of a screen runs one): its parts are that episode's, its extras
the episode's with episodes = 1 (worker.trial.robust.combine)."""

from __future__ import annotations

from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.robust import RobustSpec, draw_episode
from spinefarm.protocol.states import TrialStatus
from spinefarm.worker.trial.robust import combine


def test_one_episode_is_its_own_trial() -> None:
    r = TrialResult(TrialStatus.COMPLETE, "", distance_m=0.42, ntrt_distance_cm=40.0, speed_cm_s=1.4, work_j=3.0,
                    cot=0.9, sim_time_s=30.0, wall_time_s=2.0, mass_kg=1.5, seed=3, extras={"engine": "mujoco"})
    out = combine([r], [draw_episode(RobustSpec(1, {"friction": 0.2}), 9, 0)], 9)
    assert out.ok and (out.distance_m, out.cot, out.wall_time_s, out.seed) == (0.42, 0.9, 2.0, 9)
    assert out.extras == {"engine": "mujoco", "episodes": 1} and len(out.episodes) == 1
