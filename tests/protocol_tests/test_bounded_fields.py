"""Ranges declared on dataclass fields: one message naming the field, what came and what was expected."""

from dataclasses import dataclass

import pytest

from spinefarm.protocol.errors import ConfigError, bounded, check_fields, whole


@dataclass(frozen=True)
class _Record:
    gain_n_per_m: float = bounded(1.0, 0.0, low_inclusive=False)
    offset_cm: float | None = bounded(None, -5.0, 5.0)
    iterations: int = whole(10, 1, 100)

    def __post_init__(self) -> None:
        check_fields(self, "test ")


def test_defaults_and_an_unset_option_pass() -> None:
    assert _Record().offset_cm is None
    assert _Record(offset_cm=5.0).offset_cm == 5.0


@pytest.mark.parametrize(("kwargs", "words"), [
    ({"gain_n_per_m": 0.0}, "test gain_n_per_m out of range; received 0.0; expected a finite number in (0, inf]"),
    ({"gain_n_per_m": float("nan")}, "test gain_n_per_m out of range; received nan"),
    ({"offset_cm": 6.0}, "test offset_cm out of range; received 6.0; expected a finite number in [-5, 5]"),
    ({"iterations": 0}, "test iterations out of range; received 0; expected an integer in [1, 100]"),
    ({"iterations": 2.0}, "test iterations out of range; received 2.0"),
    ({"iterations": True}, "test iterations out of range; received True"),
])
def test_a_value_out_of_its_declared_range_is_refused_by_name(kwargs: dict, words: str) -> None:
    with pytest.raises(ConfigError) as err:
        _Record(**kwargs)
    assert str(err.value).startswith(words)


def test_the_bullet_settings_refuse_a_boolean_iteration_count() -> None:
    from spinefarm.worker.engines.bullet import BulletSettings

    with pytest.raises(ConfigError, match="solver_iterations out of range; received True"):
        BulletSettings(solver_iterations=True)
