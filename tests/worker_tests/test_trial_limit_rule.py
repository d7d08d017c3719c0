"""The trial's wall-clock limit as docs/reliability.md states it, figures by hand: max(--min-trial-limit,
8 x measured wall s per simulated s x simulated s) for a kind measured here; before that, 10 x the larger of
the minimum and the slowest measured rate scaled to the task's step x its simulated seconds."""

from __future__ import annotations

import signal

import pytest

from spinefarm.worker.service.sandbox import TrialLimit, _exit_text


def test_defaults_are_the_documented_30_s_8x_and_10x() -> None:
    lim = TrialLimit()
    assert (lim.min_s, lim.factor, lim.first_factor) == (30.0, 8.0, 10.0)
    # nothing measured: 10 x max(30 s, no rate) for any length, also a length of 0 or less
    assert lim.limit_s(20.0) == 300.0
    assert lim.limit_s(0.0) == 300.0 and lim.limit_s(-1.0) == 300.0


def test_a_measured_kind_gets_8x_its_rate_and_never_less_than_the_minimum() -> None:
    lim = TrialLimit()
    lim.observe(4.0, 2.0, kind="screen", dt_s=0.002)        # 2 wall s per simulated s
    assert lim.limit_s(20.0, "screen", 0.002) == pytest.approx(8 * 2.0 * 20.0)   # 320 s
    assert lim.limit_s(1.0, "screen", 0.002) == 30.0        # 8 x 2 x 1 = 16 s < the 30 s minimum
    assert lim.limit_s(0.0, "screen") == 300.0              # no length: the first-trial guess
    # a second, faster trial moves the rate a fifth of the way: 0.8 x 2 + 0.2 x 0.5 = 1.7
    lim.observe(1.0, 2.0, kind="screen", dt_s=0.002)
    assert lim.limit_s(20.0, "screen") == pytest.approx(8 * 1.7 * 20.0)
    # nothing measured (no wall time, no simulated time) changes nothing
    lim.observe(0.0, 2.0, kind="screen")
    lim.observe(3.0, 0.0, kind="screen")
    assert lim.limit_s(20.0, "screen") == pytest.approx(8 * 1.7 * 20.0)


def test_a_fast_kinds_rate_follows_its_trials_down() -> None:
    # 0.1 then 0.05 wall s per simulated s: 0.8 x 0.1 + 0.2 x 0.05 = 0.09, so 8 x 0.09 x 100 s = 72 s
    lim = TrialLimit()
    lim.observe(0.2, 2.0, kind="fast")
    lim.observe(0.1, 2.0, kind="fast")
    assert lim.limit_s(100.0, "fast") == pytest.approx(72.0)


def test_an_unmeasured_kind_takes_10x_the_slowest_rate_scaled_to_its_finer_step() -> None:
    lim = TrialLimit()
    lim.observe(4.0, 2.0, kind="screen", dt_s=0.002)        # 2 s/s at 2 ms
    lim.observe(1.0, 2.0, kind="other", dt_s=None)          # 0.5 s/s, step unknown
    # a judge at 0.25 ms: 8x finer than the 2 ms screen, so 2 x 8 x 20 s = 320 s, x 10
    assert lim.limit_s(20.0, "judge", 0.00025) == pytest.approx(10 * 2.0 * 8 * 20.0)
    # a coarser step is not scaled down; an unknown step is not scaled
    assert lim.limit_s(20.0, "judge", 0.004) == pytest.approx(10 * 2.0 * 20.0)
    assert lim.limit_s(20.0, "judge", None) == pytest.approx(10 * 2.0 * 20.0)
    # a short one: the 30 s minimum is the larger, 10 x 30 s
    assert lim.limit_s(1.0, "judge", 0.002) == 300.0


def test_a_rate_measured_without_its_step_is_not_scaled() -> None:
    lim = TrialLimit()
    lim.observe(6.0, 2.0, kind="screen", dt_s=None)         # 3 s/s, step unknown
    assert lim.limit_s(20.0, "judge", 0.00025) == pytest.approx(10 * 3.0 * 20.0)


@pytest.mark.parametrize(("min_s", "factor", "first"), [(0.0, 8.0, 10.0), (30.0, 0.9, 10.0), (30.0, 8.0, 0.9)])
def test_settings_out_of_range_are_refused_by_name(min_s: float, factor: float, first: float) -> None:
    with pytest.raises(ValueError, match=f"min_s={min_s}, factor={factor}, first_factor={first}"):
        TrialLimit(min_s, factor, first)


def test_factors_of_one_are_allowed() -> None:
    lim = TrialLimit(1.0, 1.0, 1.0)
    lim.observe(2.0, 1.0, kind="k")
    assert lim.limit_s(5.0, "k") == 10.0
    assert lim.limit_s(5.0, "other") == 10.0


@pytest.mark.parametrize(("code", "text"), [(-int(signal.SIGSEGV), "signal SIGSEGV"),
                                            (-int(signal.SIGKILL), "signal SIGKILL"),
                                            (3, "exit code 3"), (0, "exit code 0"), (None, "exit code None"),
                                            (-999, "exit code -999")])
def test_a_trial_process_end_is_named_by_its_signal_or_exit_code(code: int | None, text: str) -> None:
    assert _exit_text(code) == text
