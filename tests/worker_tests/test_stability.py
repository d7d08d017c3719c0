"""The stable-step estimate of the explicit string network, and what the trial does with it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from spinefarm.protocol.errors import ConfigError
from spinefarm.protocol.states import TrialStatus
from spinefarm.robot.morphology.model import ControlSpec, Morphology
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.morphology.variants import with_density_factor, with_gains, with_strings
from spinefarm.worker.sim.stability import estimate_stable_step
from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, simulate
from tests.worker_tests.helpers import mass_between_anchors


def test_estimate_matches_the_analytic_two_spring_oscillator():
    spec = mass_between_anchors(10.0, anchor_density=0.014 * 1e9, stiffness=1000.0)
    morph = Morphology("triple", spec, ControlSpec(cpg_tags=(), impedance=()), scored_segment=1)
    est = estimate_stable_step(morph)
    m = 0.014 * math.pi * 0.25 * 10.0
    assert est.omega_max_rad_s == pytest.approx(math.sqrt(2 * 1000.0 / m), rel=1e-3)
    assert est.dt_damping_limit_s == math.inf  # these strings have no damping


def test_limit_scales_with_stiffness():
    base = load_morphology("tetraspine-ntrt")
    soft = estimate_stable_step(base)
    stiff = estimate_stable_step(with_strings(base, stiffness_n_per_m=600_000.0))
    assert stiff.omega_max_rad_s == pytest.approx(soft.omega_max_rad_s * math.sqrt(600.0), rel=1e-6)
    assert stiff.dt_limit_s < 1e-3 < soft.dt_limit_s


def test_unstable_step_is_refused_with_the_estimate_in_the_message():
    morph = with_strings(load_morphology("tetraspine-ntrt"), stiffness_n_per_m=600_000.0)
    with pytest.raises(ConfigError) as exc:
        simulate(morph, random_unit_params(morph, 1), TrialConfig(duration_s=0.1, dt_s=2e-3), 1)
    text = str(exc.value)
    assert "omega_max" in text and "expected dt_s <=" in text and "received 0.002" in text


def test_auto_step_runs_the_stiff_case_stably():
    morph = with_strings(load_morphology("tetraspine-ntrt"), stiffness_n_per_m=600_000.0)
    u = random_unit_params(morph, 1)
    est = estimate_stable_step(morph)
    r = simulate(morph, u, TrialConfig(duration_s=0.3, auto_dt=True), 1).result
    assert r.status == TrialStatus.COMPLETE, r.reason
    assert r.extras["dt_s"] == pytest.approx(0.5 * est.dt_limit_s)
    # and forcing a step twice the estimate past the refusal does diverge
    forced = simulate(morph, u, TrialConfig(duration_s=0.3, dt_s=2e-3, refuse_unstable_dt=False), 1).result
    assert forced.status == TrialStatus.FAILED and forced.reason.startswith("diverged")


def test_every_builtin_is_stable_at_its_default_step():
    from spinefarm.robot.morphology.registry import builtin_names

    for name in builtin_names():
        est = estimate_stable_step(load_morphology(name))
        assert np.isfinite(est.omega_max_rad_s)
        if name == "tetraspine-hardware":  # 600,000 N/m cables: the hard case, needs ~0.5 ms
            assert est.dt_limit_s < TrialConfig().step_s
        else:
            assert est.dt_limit_s > TrialConfig().step_s, name


def test_light_segments_are_limited_by_damping_and_run_at_the_auto_step():
    light = with_density_factor(load_morphology("tetraspine-ntrt"), 0.02)  # 49 g segments, 38 cm levers
    est = estimate_stable_step(light)
    assert est.dt_damping_limit_s < est.dt_spring_limit_s  # damping rates, not stiffness, set the limit
    u = random_unit_params(light, 1)
    ok = simulate(light, u, TrialConfig(duration_s=0.5, auto_dt=True), 1).result
    assert ok.status == TrialStatus.COMPLETE, ok.reason
    forced = simulate(light, u, TrialConfig(duration_s=0.5, dt_s=10 * est.dt_limit_s, refuse_unstable_dt=False),
                      1).result
    assert forced.status == TrialStatus.FAILED and forced.reason.startswith("diverged")


def _edge_unit(morph: Morphology) -> np.ndarray:
    u = random_unit_params(morph, 3)
    u[0] = u[1] = 1.0  # CPG frequency and amplitude at their upper bounds
    return u


@pytest.mark.parametrize("case", ["cpg-edge", "tension-saturation", "large-pretension", "slack-taut-chatter"])
def test_controller_side_hard_cases_stay_sane_at_the_default_step(case):
    base = load_morphology("tetraspine-ntrt")
    morph = {"cpg-edge": base, "tension-saturation": with_strings(base, max_tension_n=5.0),
             "large-pretension": with_strings(base, pretension_n=60.0),
             "slack-taut-chatter": with_gains(base, control_length_cm=None)}[case]
    u = _edge_unit(morph) if case in ("cpg-edge", "slack-taut-chatter") else random_unit_params(morph, 3)
    # these change the control, not the string network: the stable-step estimate is unchanged
    assert estimate_stable_step(morph).dt_limit_s == pytest.approx(estimate_stable_step(base).dt_limit_s)
    r = simulate(morph, u, TrialConfig(duration_s=1.0), 3).result
    assert r.status == TrialStatus.COMPLETE, r.reason
    assert r.distance_m < 1.0 and np.isfinite(r.work_j)  # no runaway "gait"
