"""An episode's seed is in [0, 2^31 - 1) (protocol.robust.episode_seed: what every engine's seed takes), and
spread over it: 300 episodes' seeds, all below 2^31 - 1, the largest above 2^30, all distinct."""

from __future__ import annotations

from spinefarm.protocol.robust import episode_seed


def test_episode_seeds_fill_their_range() -> None:
    seeds = [episode_seed(trial, k) for trial in (0, 7, 123456) for k in range(100)]
    assert all(0 <= s < 2**31 - 1 for s in seeds)
    assert max(seeds) > 2**30 and len(set(seeds)) == len(seeds)
