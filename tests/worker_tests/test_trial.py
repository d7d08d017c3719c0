"""Whole trials: settling, moving, failing cleanly, determinism, bad input."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from spinefarm.protocol.errors import ParameterError
from spinefarm.protocol.states import TrialStatus
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.morphology.structure import StringMaterial
from spinefarm.robot.morphology.variants import with_strings
from spinefarm.robot.spaces import controller_space, param_space
from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, simulate


def test_passive_tetraspine_settles_and_holds_its_shape():
    morph = load_morphology("tetraspine")
    u = random_unit_params(morph, 3)
    u[1] = 0.0  # amplitude coefficient 0: every CPG output is zero
    out = simulate(morph, u, TrialConfig(duration_s=5.0, record_every_s=0.5), seed=3)
    assert out.result.status == TrialStatus.COMPLETE
    poses = out.trajectory.arrays()["poses"]
    gaps = np.linalg.norm(np.diff(poses[:, :, :3], axis=1), axis=2)  # (frames, n_segments - 1)
    assert gaps.min() > 0.5 * gaps[0].min()  # contracts to its control lengths but does not collapse
    assert np.abs(gaps[-1] - gaps[-5]).max() < 0.5  # shape held over the last 2 s (cm)
    assert poses[-1, :, 1].min() > 5.0  # segments stand, COMs well above the ground
    creep_cm_s = np.linalg.norm(poses[-1, :, :3] - poses[-2, :, :3], axis=1).max() / 0.5
    assert creep_cm_s < 2.0
    assert np.all(out.trajectory.arrays()["cpg_output_cm_s"] == 0.0)


def test_controlled_trial_runs_and_moves():
    morph = load_morphology("tetraspine")
    r = simulate(morph, random_unit_params(morph, 7), TrialConfig(duration_s=2.0), seed=7).result
    assert r.status == TrialStatus.COMPLETE, r.reason
    assert r.distance_m > 0.005 and r.sim_time_s == pytest.approx(2.0)
    assert r.work_j > 0 and math.isfinite(r.cot) and r.cot > 0
    assert r.speed_cm_s == pytest.approx(r.distance_m * 100 / 2.0)


def test_sidewinding_space_runs():
    morph = load_morphology("tetraspine")
    r = simulate(morph, random_unit_params(morph, 2, "sidewinding"), TrialConfig(duration_s=0.5), 2,
                 controller="sidewinding").result
    assert r.status == TrialStatus.COMPLETE and r.distance_m > 0


def test_absurd_stiffness_fails_as_diverged_not_an_exception():
    morph = with_strings(load_morphology("tetraspine-ntrt"), stiffness_n_per_m=1e8)
    cfg = TrialConfig(duration_s=1.0, refuse_unstable_dt=False)  # run it anyway
    r = simulate(morph, random_unit_params(morph, 1), cfg, seed=1).result
    assert r.status == TrialStatus.FAILED
    assert r.reason.startswith("diverged")
    assert r.sim_time_s < 1.0  # stopped early, partial metrics kept
    assert math.isfinite(r.distance_m) and r.distance_m < 100.0


def test_bad_parameters_raise_named_errors():
    morph = load_morphology("tetraspine-ntrt")
    with pytest.raises(ParameterError, match="wrong length"):
        simulate(morph, np.zeros(5), TrialConfig(duration_s=0.01))
    bad = random_unit_params(morph, 1)
    bad[3] = np.nan
    with pytest.raises(ParameterError, match="non-finite"):
        simulate(morph, bad, TrialConfig(duration_s=0.01))
    named = param_space(morph).to_named(param_space(morph).from_unit(random_unit_params(morph, 1)))
    named["cpg_frequency_coef_hz"] = 99.0
    with pytest.raises(ParameterError, match="outside its bounds"):
        simulate(morph, named, TrialConfig(duration_s=0.01))


TRIAL_SNIPPET = """
import json
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.morphology.variants import with_strings
from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, simulate
m = load_morphology("tetraspine")
r = simulate(m, random_unit_params(m, 11), TrialConfig(duration_s=0.3, pose_jitter_cm=0.01), seed=11).result
d = r.to_dict(); d.pop("wall_time_s")
print(json.dumps(d))
"""


def test_deterministic_across_processes():
    outs = [subprocess.run([sys.executable, "-c", TRIAL_SNIPPET], capture_output=True, text=True, check=True)
            for _ in range(2)]
    a, b = (json.loads(o.stdout.strip().splitlines()[-1]) for o in outs)
    assert a == b
    m = load_morphology("tetraspine")
    here = simulate(m, random_unit_params(m, 11), TrialConfig(duration_s=0.3, pose_jitter_cm=0.01), seed=11).result
    assert here.distance_m == a["distance_m"] and here.work_j == a["work_j"]  # same bits
    other_seed = simulate(m, random_unit_params(m, 11), TrialConfig(duration_s=0.3, pose_jitter_cm=0.01),
                          seed=12).result
    assert other_seed.distance_m != a["distance_m"]


def test_config_rejects_bad_values_with_the_field_name():
    from spinefarm.protocol.errors import ConfigError

    with pytest.raises(ConfigError, match="dt_s"):
        TrialConfig(dt_s=0.5)
    with pytest.raises(ConfigError, match="motor_model"):
        TrialConfig(motor_model="magic")
    assert TrialConfig.from_dict(TrialConfig(dt_s=5e-4).to_dict()) == TrialConfig(dt_s=5e-4)


def test_ntrt_motor_mode_runs():
    morph = load_morphology("tetraspine-ntrt")
    r = simulate(morph, random_unit_params(morph, 4), TrialConfig(duration_s=0.5, motor_model="ntrt2014"), 4).result
    assert r.status == TrialStatus.COMPLETE and r.distance_m > 0


def test_cpg_integration_error_is_small_against_substepping():
    morph = load_morphology("tetraspine-ntrt")
    u = random_unit_params(morph, 5)
    base = simulate(morph, u, TrialConfig(duration_s=1.0), 5).result
    fine = simulate(morph, u, TrialConfig(duration_s=1.0, cpg_max_step_s=1e-3 / 8), 5).result
    assert abs(base.distance_m - fine.distance_m) <= 0.02 * max(fine.distance_m, 0.01)


@pytest.mark.parametrize("name", ["tetraspine", "octahedral-complex"])
def test_default_cpg_sub_step_keeps_the_bits_of_1ms_sub_steps_on_ntrt_networks(name):
    """A fast network (most of NTRT's space) keeps 1 ms sub-steps, at a 1 ms and at a 0.1 s update period."""
    from spinefarm.worker.control.cpg import CpgIntegrator

    morph = load_morphology(name)
    u = random_unit_params(morph, 4)
    space = controller_space(morph)
    period = morph.control.cpg_update_period_s
    assert CpgIntegrator(space.network(space.param_space.from_unit(u))).plan(period) == (1e-3, round(period / 1e-3))
    auto, fixed = (simulate(morph, u, TrialConfig(duration_s=0.5, cpg_max_step_s=cap), 4).result
                   for cap in (None, 1e-3))
    assert (auto.distance_m, auto.work_j) == (fixed.distance_m, fixed.work_j)


def test_a_2ms_screen_of_a_sidewinding_gait_takes_one_cpg_step_per_update_at_no_cost_in_accuracy():
    from spinefarm.worker.control.cpg import CpgIntegrator

    morph = load_morphology("tetraspine")
    u = random_unit_params(morph, 3, "sidewinding")
    space = controller_space(morph, "sidewinding")
    network = space.network(space.param_space.from_unit(u))
    one, fine = CpgIntegrator(network), CpgIntegrator(network, 1e-3 / 16)
    assert one.plan(2e-3) == (2e-3, 1)
    worst = 0.0
    for _ in range(1000):  # 2 s of 2 ms updates
        one.advance(2e-3)
        fine.advance(2e-3)
        worst = max(worst, float(np.max(np.abs(one.output_cm_s - fine.output_cm_s))))
    assert worst < 1e-6 * float(np.max(np.abs(fine.output_cm_s)))
    # the trial sees it only through the contacts' sensitivity (a 1e-9 cm start jitter moves it ~0.3 %)
    auto, fixed = (simulate(morph, u, TrialConfig(duration_s=2.0, engine="mujoco", dt_s=2e-3, cpg_max_step_s=cap),
                            3, controller="sidewinding").result for cap in (None, 1e-3))
    assert abs(auto.distance_m - fixed.distance_m) <= 0.02 * fixed.distance_m


def test_stiff_string_string_material_validation():
    with pytest.raises(Exception, match="stiffness_n_per_m"):
        StringMaterial(stiffness_n_per_m=-1.0)


@pytest.mark.parametrize("engine", ["bullet", "mujoco"])
def test_settle_phase_scores_locomotion_from_the_settled_pose(engine):
    """With no CPG output a Tetraspine 'moves' centimetres in its first second just settling; after a
    settle phase that motion is not scored, while NTRT's distance still counts from the start."""
    morph = load_morphology("tetraspine-ntrt")
    u = random_unit_params(morph, 1)
    u[1] = 0.0
    raw = simulate(morph, u, TrialConfig(duration_s=1.0, engine=engine), 1).result
    settled = simulate(morph, u, TrialConfig(duration_s=1.0, settle_s=1.0, engine=engine), 1).result
    assert raw.ok and settled.ok
    assert raw.distance_m > 0.02 and settled.distance_m < 0.1 * raw.distance_m
    assert settled.sim_time_s == pytest.approx(1.0) and settled.extras["settle_s"] == pytest.approx(1.0)
    assert settled.ntrt_distance_cm > 0.5 * raw.ntrt_distance_cm  # from the start, settling included
    assert raw.extras["settle_s"] == 0.0
    with pytest.raises(Exception, match="settle_s"):
        TrialConfig(settle_s=-1.0)


def test_a_reused_setup_builds_the_controller_space_once(monkeypatch):
    """The NTRT spaces take milliseconds to build; trials sharing a set-up share the space too."""
    from spinefarm.robot import spaces
    from spinefarm.worker.trial.setup import SetupCache

    built = []
    original = spaces.SPACES["ntrt"]
    monkeypatch.setitem(spaces.SPACES, "ntrt", lambda morph: built.append("ntrt") or original(morph))
    morph = load_morphology("tetrahedral-complex")
    cfg = TrialConfig(duration_s=0.05, engine="mujoco", dt_s=0.002)
    cache = SetupCache()
    results = [simulate(morph, random_unit_params(morph, s, "ntrt"), cfg, s, controller="ntrt", setup=cache).result
               for s in (1, 2, 3)]
    assert all(r.ok for r in results)
    # random_unit_params builds one per call (its length); the three trials add one between them
    assert len(built) == 3 + 1
