"""The MuJoCo backend: the same model as Bullet behind the same seam, its fused loop, reuse and terrain."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys

import mujoco
import numpy as np
import pytest

from spinefarm.protocol.errors import ConfigError
from spinefarm.protocol.states import TrialStatus
from spinefarm.robot.bodies import build_bodies
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.scene import GroundSpec, SceneConfig, build_terrain, surface_height_cm
from spinefarm.worker.engines.mujoco import MujocoPhysics, MujocoSettings
from spinefarm.worker.sim import strings as sk
from spinefarm.worker.trial.setup import SetupCache
from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, simulate
from tests.worker_tests.helpers import ENGINES, PassiveRig, two_rod_structure

V_CM_S, A_CM_S2 = 24.0, 10000.0


def _driven_rest_lengths(engine: str, dt: float, seconds: float = 0.4) -> np.ndarray:
    """A string between two free rods driven 5 cm shorter by the motor: its rest length over time."""
    rig = PassiveRig(two_rod_structure(10.0), dt=dt, engine=engine)
    p = rig.bank.params
    p[0, sk.P_MODE], p[0, sk.P_DRIVE] = sk.MODE_DRIVEN, rig.bank.state[0, sk.S_REST] - 5.0
    p[0, sk.P_V], p[0, sk.P_A], p[0, sk.P_TMAX] = V_CM_S, A_CM_S2, 1e9
    p[0, sk.P_LMIN] = p[0, sk.P_LACT] = 0.1
    rests = [rig.bank.state[0, sk.S_REST]]
    for _ in range(int(round(seconds / dt))):
        rig.step()
        rests.append(rig.bank.state[0, sk.S_REST])
    rig.close()
    return np.array(rests)


@pytest.mark.parametrize("engine", ENGINES)
def test_motor_limits_do_not_depend_on_the_step_in_the_engine(engine):
    times = []
    for dt in (2e-3, 1e-3, 2.5e-4):
        rests = _driven_rest_lengths(engine, dt)
        assert np.max(np.abs(np.diff(rests))) / dt <= V_CM_S + 1e-9
        times.append(np.argmax(np.abs(rests - rests[-1]) < 1e-6) * dt)
        assert abs(rests[0] - rests[-1] - 5.0) < 1e-9  # arrived
    expected = 5.0 / V_CM_S + V_CM_S / A_CM_S2
    assert np.allclose(times, expected, rtol=0.02), times


SNIPPET = """
import json
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, simulate
m = load_morphology("tetraspine")
cfg = TrialConfig(duration_s=0.3, pose_jitter_cm=0.01, engine="mujoco")
r = simulate(m, random_unit_params(m, 11), cfg, seed=11).result
d = r.to_dict(); d.pop("wall_time_s")
print(json.dumps(d))
"""


def test_bit_identical_across_processes():
    outs = [subprocess.run([sys.executable, "-c", SNIPPET], capture_output=True, text=True, check=True)
            for _ in range(2)]
    a, b = (json.loads(o.stdout.strip().splitlines()[-1]) for o in outs)
    assert a == b and a["extras"]["engine"] == "mujoco"
    m = load_morphology("tetraspine")
    cfg = TrialConfig(duration_s=0.3, pose_jitter_cm=0.01, engine="mujoco")
    here = simulate(m, random_unit_params(m, 11), cfg, seed=11).result
    assert here.distance_m == a["distance_m"] and here.work_j == a["work_j"]
    assert simulate(m, random_unit_params(m, 11), cfg, seed=12).result.distance_m != a["distance_m"]


def test_fused_loop_gives_the_same_bits_as_the_step_by_step_loop():
    """Recording runs the loop through the engine seam step by step; without it, one compiled call runs
    many steps. Both must agree exactly."""
    m = load_morphology("tetraspine")
    u = random_unit_params(m, 3)
    fused = simulate(m, u, TrialConfig(duration_s=0.5, engine="mujoco"), 3).result
    stepwise = simulate(m, u, TrialConfig(duration_s=0.5, engine="mujoco", record_every_s=0.05), 3).result
    assert fused.distance_m == stepwise.distance_m and fused.work_j == stepwise.work_j > 0


def test_reused_setup_gives_the_same_bits_as_a_fresh_one():
    m = load_morphology("tetraspine-ntrt")
    cfg = TrialConfig(duration_s=0.3, engine="mujoco", pose_jitter_cm=0.01)
    cache = SetupCache()
    reused = [simulate(m, random_unit_params(m, s), cfg, s, setup=cache).result for s in (1, 2, 1)]
    assert cache.get(m, cfg, None).scenes_built == 1  # one model compiled, then reset
    fresh = simulate(m, random_unit_params(m, 1), cfg, 1).result
    assert reused[0].distance_m == reused[2].distance_m == fresh.distance_m
    assert reused[1].distance_m != reused[0].distance_m
    # a shorter rung with a settle phase shares the set-up (and the compiled model) of the run
    rung = dataclasses.replace(cfg, duration_s=0.2, settle_s=0.1)
    short = simulate(m, random_unit_params(m, 1), rung, 1, setup=cache).result
    assert cache.get(m, rung, None).scenes_built == 1
    assert short.distance_m == simulate(m, random_unit_params(m, 1), rung, 1).result.distance_m
    cache.close()


def test_absurd_stiffness_fails_as_diverged_on_mujoco(tmp_path, monkeypatch):
    from spinefarm.robot.morphology.variants import with_strings

    monkeypatch.chdir(tmp_path)
    morph = with_strings(load_morphology("tetraspine-ntrt"), stiffness_n_per_m=1e8)
    cfg = TrialConfig(duration_s=1.0, refuse_unstable_dt=False, engine="mujoco")
    r = simulate(morph, random_unit_params(morph, 1), cfg, seed=1).result
    assert r.status == TrialStatus.FAILED and r.reason.startswith("diverged"), r.reason
    assert r.sim_time_s < 1.0 and np.isfinite(r.distance_m) and r.distance_m < 100.0
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()  # MuJoCo's warnings go to logging, not a file


def test_spec_file_robot_runs_on_mujoco(tmp_path, capsys):
    from spinefarm.cli.main import main
    from tests.worker_tests.test_specfile import GOOD

    path = tmp_path / "chain.yaml"
    path.write_text(GOOD)
    assert main(["trial", str(path), "--random-seed", "2", "--duration", "0.3", "--engine", "mujoco", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["morphology"] == "bar-chain" and out["status"] == "complete"
    assert out["extras"]["engine"] == "mujoco" and out["extras"]["dt_s"] > 0


@pytest.mark.parametrize("cfg", [SceneConfig(), SceneConfig(kind="slope", slope_deg=10.0),
                                 SceneConfig(kind="rough", rough_amplitude_cm=3.0, rough_seed=4),
                                 SceneConfig(kind="obstacles", obstacle_spacing_cm=40.0)])
def test_terrain_heights_agree_with_mujoco(cfg):
    terrain = build_terrain(cfg, 0.5, (-50.0, 50.0))
    scene = MujocoPhysics([], terrain)
    mujoco.mj_forward(scene.model, scene.data[0])
    rng = np.random.default_rng(0)
    xs, zs = rng.uniform(-200, 200, 40), rng.uniform(-200, 200, 40)
    geomid = np.zeros(1, dtype=np.int32)
    theirs = np.array([200.0 - mujoco.mj_ray(scene.model, scene.data[0], np.array([x, 200.0, z]),
                                             np.array([0.0, -1.0, 0.0]), None, 1, -1, geomid)
                       for x, z in zip(xs, zs, strict=True)])
    ours = surface_height_cm(terrain, xs, zs)
    if cfg.kind == "rough":
        assert np.all(ours >= theirs - 1e-6) and np.max(ours - theirs) < 2 * cfg.rough_amplitude_cm
        assert np.ptp(theirs) > cfg.rough_amplitude_cm
    else:
        assert np.allclose(ours, theirs, atol=1e-6)


@pytest.mark.parametrize("engine", ENGINES)
def test_friction_is_the_product_of_ground_and_rod(engine):
    """The octahedral complex: rods 0.5 on ground 0.5, so 0.25 in Bullet. On a 20 degree slope
    (tan = 0.36) it slides with the product and would hold with MuJoCo's default max (0.5); on 10 degrees
    (tan = 0.18) it holds after settling onto the slope (its second second moves less than 1 cm)."""
    morph = load_morphology("octahedral-complex")
    u = random_unit_params(morph, 1)
    u[1] = 0.0  # no CPG output
    moved = {}
    for deg in (10.0, 20.0):
        for seconds in (1.0, 2.0):
            cfg = TrialConfig(duration_s=seconds, engine=engine, scene=SceneConfig(kind="slope", slope_deg=deg))
            r = simulate(morph, u, cfg, 1).result
            assert r.ok, r.reason
            moved[deg, seconds] = r.distance_m
    assert moved[20.0, 2.0] - moved[20.0, 1.0] > 1.0, moved  # sliding faster and faster
    assert moved[10.0, 2.0] - moved[10.0, 1.0] < 0.01, moved


def _pushed_segment_slides_cm(engine: str, force: np.ndarray, options: dict | None = None) -> float:
    """One octahedral segment dropped on flat ground, settled 0.3 s, then pushed 0.4 s by `force` at its COM."""
    from spinefarm.worker.engines.base import engine_class
    from spinefarm.worker.trial.setup import TrialSetup

    setup = TrialSetup(load_morphology("octahedral-complex"), TrialConfig(engine=engine,
                                                                          engine_options=options or {}), None)
    zero = np.zeros((1, 1, 3))
    with engine_class(engine)(setup.bodies[:1], setup.terrain, setup.dt, setup.settings) as world:
        for k in range(700):
            world.read_poses()
            if k == 300:
                start = world.read_poses()[0, 0, [0, 2]].copy()
            world.apply_wrenches(force[None, None] if k >= 300 else zero, zero)
            world.step()
        return float(np.hypot(*(world.read_poses()[0, 0, [0, 2]] - start)))


@pytest.mark.parametrize("engine", ENGINES)
def test_friction_is_coulombs_in_every_direction(engine):
    """A push of 0.8 of the Coulomb limit mu m g holds in every horizontal direction, and under 1.2 of it the
    segment slides against mu = 0.25 (from its slide, (F - m a) / (m g)), also on the diagonal between MuJoCo's
    contact axes, where its pyramidal cone gives only mu / sqrt(2) (and slides at 0.8)."""
    body = build_bodies(load_morphology("octahedral-complex").structure)[0]
    weight = body.mass_kg * 981.0
    diagonal = np.array([1.0, 0.0, 1.0]) / np.sqrt(2.0)
    for direction in (np.array([1.0, 0.0, 0.0]), diagonal):
        assert _pushed_segment_slides_cm(engine, 0.8 * 0.25 * weight * direction) < 0.05
        slid_cm = _pushed_segment_slides_cm(engine, 1.2 * 0.25 * weight * direction)
        mu = (1.2 * 0.25 * weight - body.mass_kg * 2.0 * slid_cm / 0.4 ** 2) / weight
        assert mu == pytest.approx(0.25, rel=0.05), (direction, slid_cm)
    if engine == "mujoco":  # the pyramid MuJoCo offers is a diamond: the diagonal push slides
        assert _pushed_segment_slides_cm(engine, 0.8 * 0.25 * weight * diagonal, {"cone": "pyramidal"}) > 1.0


def test_filtered_pairs_pass_through_each_other():
    bodies = build_bodies(load_morphology("tetraspine-ntrt").structure)
    terrain = build_terrain(SceneConfig(collision_filter="neighbours"), 0.5, (0, 0))
    for settings, neighbours_touch in ((MujocoSettings(segment_contacts="scene"), True),
                                       (MujocoSettings(segment_contacts="off"), False),
                                       (MujocoSettings(segment_contacts="auto"), False)):
        scene = MujocoPhysics(bodies, terrain, 1e-3, settings)
        up = bodies[0].com_cm + np.array([0.0, 100.0, 0.0])  # well above the ground
        scene.qpos[0][:3, :3] = up  # segment 2 onto segment 0, and its neighbour 1 too
        mujoco.mj_forward(scene.model, scene.data[0])
        pairs = {tuple(sorted((scene.model.geom_bodyid[c.geom1] - 1, scene.model.geom_bodyid[c.geom2] - 1)))
                 for c in scene.data[0].contact[:scene.data[0].ncon]}
        assert (0, 2) not in pairs
        assert ((0, 1) in pairs) == neighbours_touch
        # "auto" leaves them out of the model, and its guard sees that they would touch
        steps, why = scene.contact_free_steps(10)
        assert (steps, bool(why)) == ((0, True) if settings.segment_contacts == "auto" else (10, False))
        scene.close()


def test_the_contact_guard_is_silent_while_segments_are_apart():
    bodies = build_bodies(load_morphology("tetraspine-ntrt").structure)
    scene = MujocoPhysics(bodies, build_terrain(SceneConfig(), 0.5, (0, 0)), 1e-3, MujocoSettings())
    assert scene.contact_free_steps(10) == (10, "")
    # segment 1 flying at segment 0: the faster, the sooner the guard must look again, until not even one
    # step is safe without the contacts
    looks = []
    for speed_cm_s in (1e1, 1e2, 3e2, 1e3, 3e3, 1e4, 1e5):
        scene.qvel[0][1, :3] = [0.0, 0.0, -speed_cm_s]
        looks.append(scene.contact_free_steps(10))
    steps = [s for s, _ in looks]
    assert steps == sorted(steps, reverse=True) and steps[0] == 10 and steps[-1] == 0, looks
    assert any(0 < s < 10 for s in steps), looks
    assert looks[-1][1].startswith("gap") and all(why == "" for s, why in looks if s), looks
    scene.close()


def test_segment_distance_agrees_with_dense_sampling():
    from spinefarm.worker.engines.contact_guard import _segment_distance

    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 1.0, 401)[:, None]
    for _ in range(50):
        p1, q1, p2, q2 = rng.normal(size=(4, 3))
        if _ < 5:
            q2 = p2 + (q1 - p1) * 0.5  # parallel segments
        a, b = p1 + t * (q1 - p1), p2 + t * (q2 - p2)
        sampled = np.min(np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2))
        exact = _segment_distance(p1, q1, p2, q2)
        assert exact <= sampled + 1e-12 and sampled - exact < 1e-2


@pytest.mark.parametrize(("name", "controller", "seconds", "needs_contacts"),
                         [("tetraspine", "sidewinding", 1.0, False), ("ribbed", None, 0.3, True)])
def test_auto_segment_contacts_give_the_bits_of_modelled_ones(name, controller, seconds, needs_contacts):
    """Left out while no segment comes near (the Tetraspine), run again with them when one does (the
    ribbed spine's ribs start 2 mm apart): either way the same result as modelling them throughout."""
    morph = load_morphology(name)
    u = random_unit_params(morph, 1, controller)
    runs = {mode: simulate(morph, u, TrialConfig(duration_s=seconds, engine="mujoco",
                                                 engine_options={"segment_contacts": mode}), 1,
                           controller=controller).result
            for mode in ("scene", "auto")}
    assert runs["auto"].distance_m == runs["scene"].distance_m and runs["auto"].work_j == runs["scene"].work_j
    assert runs["auto"].extras.get("segment_contacts", "").startswith("modelled") == needs_contacts


def test_segments_that_come_near_are_watched_closer_not_modelled_at_once():
    """A fast sidewinding gait whose segments come within 3.3 cm of each other at 0.66 s, faster than a
    look every 10 ms could vouch for: the guard looks again sooner instead of running the trial again
    with the contacts, and the result is still the bits of modelling them throughout."""
    morph = load_morphology("tetraspine")
    u = np.array([0.7357, 0.2892, 0.9969, 0.9913, 0.9932, 0.4873, 0.2978, 0.3533, 0.4918])
    runs = {mode: simulate(morph, u, TrialConfig(duration_s=1.0, settle_s=1.0, engine="mujoco", dt_s=2e-3,
                                                 engine_options={"segment_contacts": mode}), 1,
                           controller="sidewinding").result for mode in ("scene", "auto")}
    assert runs["auto"].distance_m == runs["scene"].distance_m and runs["auto"].work_j == runs["scene"].work_j
    assert "segment_contacts" not in runs["auto"].extras, runs["auto"].extras
    assert runs["auto"].distance_m > 0.02  # it does move


def test_proxies_rest_like_capsules_on_flat_ground():
    """Rod-end spheres touch a plane where the capsules' end caps would: same resting pose."""
    morph = load_morphology("tetraspine-ntrt")
    u = random_unit_params(morph, 1)
    u[1] = 0.0
    ends = [simulate(morph, u, TrialConfig(duration_s=1.0, engine="mujoco", record_every_s=1.0,
                                           engine_options={"contact_geometry": g}), 1).trajectory.arrays()["poses"][-1]
            for g in ("ends", "capsules")]
    assert np.abs(ends[0][:, 1] - ends[1][:, 1]).max() < 0.05  # heights within 0.5 mm


def test_cylinder_rods_are_bullets_shape_and_rest_at_its_heights():
    """contact_geometry "cylinders": one MuJoCo cylinder per rod (no end proxies), resting where Bullet's rest."""
    morph = load_morphology("tetraspine-ntrt")
    bodies = build_bodies(morph.structure)
    physics = MujocoPhysics(bodies, GroundSpec(friction=morph.ground_friction),
                            settings=MujocoSettings(contact_geometry="cylinders"))
    types = physics.model.geom_type[physics.model.geom_bodyid > 0]
    assert np.count_nonzero(types == mujoco.mjtGeom.mjGEOM_CYLINDER) == sum(len(b.rods) for b in bodies) == len(types)
    physics.close()
    u = random_unit_params(morph, 1)
    u[1] = 0.0
    heights = {name: simulate(morph, u, TrialConfig(duration_s=1.0, engine=engine, record_every_s=1.0,
                                                    engine_options=options), 1).trajectory.arrays()["poses"][-1][:, 1]
               for name, engine, options in (("bullet", "bullet", {}),
                                             ("cylinders", "mujoco", {"contact_geometry": "cylinders"}))}
    assert np.abs(heights["cylinders"] - heights["bullet"]).max() < 0.1  # within 1 mm


def test_noslip_pass_is_an_option():
    with pytest.raises(ConfigError, match="noslip_iterations"):
        MujocoSettings(noslip_iterations=-1)
    morph = load_morphology("tetraspine-ntrt")
    cfg = TrialConfig(duration_s=0.3, engine="mujoco", engine_options={"noslip_iterations": 20})
    scene = SetupCache().get(morph, cfg, None)
    r = simulate(morph, random_unit_params(morph, 2), cfg, 2, setup=scene).result
    assert r.ok, r.reason
    assert scene._scene.model.opt.noslip_iterations == 20


def test_bad_engine_options_are_named():
    with pytest.raises(ConfigError, match="unknown mujoco engine option 'friction_anchor'"):
        TrialConfig(duration_s=0.01, engine="mujoco", engine_options={"friction_anchor": False})
    with pytest.raises(ConfigError, match="integrator"):
        MujocoSettings(integrator="verlet")
    with pytest.raises(ConfigError, match="solimp"):
        MujocoSettings(solimp=(0.9, 0.95))
