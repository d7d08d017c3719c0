"""A world saved mid-trial (the engine's snapshot and the law's) and restored into fresh worlds goes on with the
bits of the trial that never stopped: what a promoted parameter set needs to continue from the end of its
last rung instead of simulating it again. Real MuJoCo, the production loop and law."""

from __future__ import annotations

import numpy as np
import pytest

from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.worker.control.law import ControlLaw
from spinefarm.worker.trial.loop import stepper
from spinefarm.worker.trial.setup import TrialSetup
from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params

FIRST_STEPS, MORE_STEPS = 1001, 143  # 1001: inside an interval of an interpolated CPG (every 2-4 steps),
# late enough that the motors no longer all run at their acceleration limit (which would hide the setpoints)


def _world(controller: str | None, seed: int = 3):
    """One MuJoCo world and the law of parameter set `seed` (random, of the controller's space) at step 0."""
    morph = load_morphology("tetraspine")
    cfg = TrialConfig(engine="mujoco", engine_options={"segment_contacts": "scene"})
    setup = TrialSetup(morph, cfg, controller)
    net = setup.space.network(setup.space.param_space.physical(random_unit_params(morph, seed, controller)))
    g = setup.geom
    law = ControlLaw([net], [setup.string_tables(net)], (g.body_a, g.body_b, g.anchor_a_cm, g.anchor_b_cm),
                     len(setup.bodies), cfg.cpg_max_step_s, cfg.motor_model)
    scene, _ = setup.scene(None, None, 1)
    law.begin_phase(1, setup.dt, cfg.cpg_own_step_s)
    return scene, law, stepper(scene, law)


def _bits(scene, law) -> tuple[bytes, bytes, bytes]:
    return scene.read_poses()[0].tobytes(), law.state[0].tobytes(), law.cpg_output_cm_s[0].tobytes()


@pytest.mark.parametrize("controller", ["sidewinding", None])
def test_a_world_restored_mid_trial_goes_on_with_the_same_bits(controller):
    scene, law, run = _world(controller)
    active = np.ones(1, dtype=bool)
    run(FIRST_STEPS, active)
    saved_at = scene.read_poses()[0].copy()
    saved = scene.snapshot(0), law.snapshot(0)
    run(MORE_STEPS, active)
    through = _bits(scene, law)
    assert active[0] and not np.array_equal(scene.read_poses()[0], saved_at)  # it moved on after the save

    fresh_scene, fresh_law, fresh_run = _world(controller)  # the same parameter set in new worlds
    fresh_run(FIRST_STEPS // 2, active)  # somewhere else than the save
    if controller == "sidewinding":
        assert fresh_law.cpg_every[0] == law.cpg_every[0] > 1  # the interpolated CPG: mid-interval at the save
    fresh_scene.restore(0, saved[0])
    fresh_law.restore(0, saved[1])
    fresh_run(MORE_STEPS, active)
    assert _bits(fresh_scene, fresh_law) == through
