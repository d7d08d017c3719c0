"""A robust trial's statistic over its episodes' finite values (protocol.robust.statistic): one finite value is
its own mean, q25 and min; none gives NaN. An episode's key (k, seed) is fixed once made."""

from __future__ import annotations

import dataclasses
import math

import pytest

from spinefarm.protocol.robust import EpisodeKey, statistic


@pytest.mark.parametrize("name", ["mean", "q25", "min"])
def test_one_finite_value_is_its_own_statistic_and_none_is_nan(name: str) -> None:
    assert statistic([2.5, math.nan, math.inf], name) == 2.5
    assert math.isnan(statistic([math.nan, -math.inf], name))


def test_an_episodes_key_is_fixed() -> None:
    with pytest.raises(dataclasses.FrozenInstanceError):
        EpisodeKey(0, 11).seed = 12
