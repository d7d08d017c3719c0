"""The report's line of how `--engine auto` chose: the same words for a new run and for the same run resumed
from its file (which stores the choice as JSON with sorted keys)."""

from __future__ import annotations

import json

from spinefarm.protocol.engine_choice import EngineChoice


def test_the_choice_reads_the_same_before_and_after_its_run_file():
    # a calibration lists MuJoCo first; the run file's JSON puts bullet first
    choice = EngineChoice("bullet", spearman=0.892, top_overlap=9, top_k=10, median_distance_ratio=1.252,
                          n_moving=12, shipped=True,
                          tiers={"mujoco": {"cpu_s_per_sim_s": 0.024, "step_error": 0.017},
                                 "bullet": {"cpu_s_per_sim_s": 0.298, "step_error": 0.041}})
    stored = EngineChoice.from_dict(json.loads(json.dumps(choice.to_dict(), sort_keys=True)))
    assert list(stored.tiers) == ["bullet", "mujoco"]
    assert stored.describe() == choice.describe()
    assert "CPU s per simulated s bullet 0.298, mujoco 0.024 [shipped calibration]" in choice.describe()
