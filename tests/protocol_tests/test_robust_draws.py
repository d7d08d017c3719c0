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


def test_only_what_is_asked_for_varies_and_each_factor_has_its_own_draw() -> None:
    """docs/results.md's --randomize: a factor not named stays at its neutral value (friction and mass 1, no
    jitter, the run's own scene: rough seed -1); adding one never changes the others; friction and mass are
    drawn apart (the same bound gives different factors)."""
    mass_only = [draw_episode(RobustSpec(3, {"mass": 0.2}), 5, k) for k in range(3)]
    assert [(d.friction_scale, d.start_jitter_cm, d.rough_seed) for d in mass_only] == [(1.0, 0.0, -1)] * 3
    both = [draw_episode(RobustSpec(3, {"mass": 0.2, "friction": 0.2}), 5, k) for k in range(3)]
    assert [d.mass_scale for d in both] == [d.mass_scale for d in mass_only]
    assert all(d.friction_scale != d.mass_scale for d in both)
    rough = [draw_episode(RobustSpec(3, {"scene": "rough"}), 5, k) for k in range(3)]
    assert [d.rough_seed for d in rough] == [d.seed for d in rough] and len({d.seed for d in rough}) == 3
