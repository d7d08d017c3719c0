"""An episode's draw is a value fixed by (trial seed, k) alone (protocol.robust, docs/results.md's robust
scoring): drawn twice it is the same, hashable and equal; it cannot be changed after it is drawn."""

from __future__ import annotations

import dataclasses

import pytest

from spinefarm.protocol.robust import RobustSpec, draw_episode


def test_an_episodes_draw_is_a_fixed_value() -> None:
    spec = RobustSpec(3, {"friction": 0.3, "mass": 0.2, "start_jitter_cm": 0.5})
    draws = [draw_episode(spec, 11, k) for k in range(3)]
    again = [draw_episode(spec, 11, k) for k in range(3)]
    assert draws == again and len(set(draws + again)) == 3  # three distinct worlds, each drawn the same twice
    with pytest.raises(dataclasses.FrozenInstanceError):
        draws[0].friction_scale = 1.0  # a world drawn for episode 0 is the one it runs in
