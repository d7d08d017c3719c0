"""A gait that rides on a numerical artefact is caught; an honest one holds."""

from __future__ import annotations

from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.morphology.variants import with_strings
from spinefarm.worker.tools.verify import VerifySettings, verify_trial
from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, simulate


def test_creep_artefact_is_not_reproduced_at_a_finer_step():
    # Without friction anchors a resting spine creeps at a speed proportional to dt: "locomotion" that
    # a finer step does not reproduce.
    morph = load_morphology("tetraspine-ntrt")
    u = random_unit_params(morph, 1)
    u[1] = 0.0  # no CPG output at all
    cfg = TrialConfig(duration_s=4.0, engine_options={"friction_anchor": False})
    r = simulate(morph, u, cfg, 1).result
    v = verify_trial(morph, u, cfg, 1, r.distance_m)
    assert not v.holds and v.verdict.startswith("not reproduced")
    assert v.fine_dt_s == cfg.step_s / 4 and v.relative_change > 0.05


def test_diverging_parameters_are_not_reproduced():
    stiff = with_strings(load_morphology("tetraspine-ntrt"), stiffness_n_per_m=600_000.0)
    u = random_unit_params(stiff, 1)
    cfg = TrialConfig(duration_s=0.5, dt_s=2e-3, refuse_unstable_dt=False)
    r = simulate(stiff, u, cfg, 1).result
    v = verify_trial(stiff, u, cfg, 1, max(r.distance_m, 1.0))  # pretend it reported a great distance
    assert not v.holds


def test_an_honest_gait_holds_with_perturbations():
    morph = load_morphology("tetraspine-ntrt")
    u = random_unit_params(morph, 7)
    cfg = TrialConfig(duration_s=3.0)
    r = simulate(morph, u, cfg, 7).result
    v = verify_trial(morph, u, cfg, 7, r.distance_m, VerifySettings(perturb=True, tolerance=0.1))
    assert v.holds, v.verdict
    assert v.perturbed_distance_m is not None and v.fine_status == "complete"
