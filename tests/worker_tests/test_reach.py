"""Rod pairs within reach (robot.reach) and MuJoCo's segment_contacts "reach", on real MuJoCo models."""

from __future__ import annotations

import textwrap
from pathlib import Path
from statistics import median

import mujoco
import numpy as np
import pytest

from spinefarm.robot.bodies import build_bodies, build_strings
from spinefarm.robot.morphology.registry import builtin_names, load_morphology
from spinefarm.robot.reach import REACH_MARGIN_CM, reachable_rod_pairs
from spinefarm.robot.scene import SceneConfig, build_terrain
from spinefarm.worker.engines.contact_guard import _segment_distance
from spinefarm.worker.engines.mujoco import MujocoPhysics
from spinefarm.worker.engines.mujoco_model import MujocoSettings
from spinefarm.worker.tools.accuracy import DISTANCE_FLOOR_M, rel
from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, simulate

# segment 0 and 1: a short hub rod carrying both string anchors and a far rod 40-60 cm out along x; two stiff
# strings hold the hubs at most 10 cm (plus 1.4 cm of stretch) apart, so a hub can never reach the other
# segment's far rod (but the far rods can swing into each other about the hubs' common axis)
HUB_AND_FAR_ROD = textwrap.dedent("""\
    name: hub-and-far-rod
    segments:
      count: 2
      nodes:
        a: [0, 0, 0]
        b: [0, 2, 0]
        c: [40, 1, 0]
        d: [60, 1, 0]
      rods:
        - [a, b, bar]
        - [c, d, bar]
      transforms:
        - translate: [0, 3, "-10 * i"]
    joints:
      - {tag: tie, strings: [[a, a], [b, b]]}
    rod_materials:
      bar: {radius_cm: 0.5, density_kg_per_cm3: 0.014, friction: 0.5}
    string_materials:
      tie: {stiffness_n_per_m: 5000}
    control:
      cpg_tags: [tie]
      impedance:
        tie: {position_gain_n_per_m: 500, velocity_gain_n_s_per_m: 50}
      cpg_update_period_s: 0.01
    duration_s: 1
""")


def _pairs(morph) -> tuple[np.ndarray, list]:
    bodies = build_bodies(morph.structure)
    n = len(bodies)
    rows = reachable_rod_pairs(morph.structure, bodies, build_strings(morph.structure, bodies),
                               [(a, b) for a in range(n) for b in range(a + 1, n)])
    return rows, bodies


def _build_gap_cm(bodies, a: int, i: int, b: int, j: int) -> float:
    ends = []
    for body, k in ((bodies[a], i), (bodies[b], j)):
        rod = body.rods[k]
        half = rod.rotation[:, 1] * (rod.length_cm / 2)
        ends.append((body.com_cm + rod.centre_cm - half, body.com_cm + rod.centre_cm + half, rod.radius_cm))
    (p1, q1, r1), (p2, q2, r2) = ends
    return _segment_distance(p1, q1, p2, q2) - r1 - r2


@pytest.mark.parametrize("name", builtin_names())
def test_reachable_pairs_of_every_builtin(name):
    """Rows (segment a, rod, segment b, rod) with a < b, never one segment with itself, and every rod pair
    that is within reach in the build pose (a pose the structure takes) among them."""
    rows, bodies = _pairs(load_morphology(name))
    assert rows.shape[1] == 4 and len(rows) and (rows[:, 0] < rows[:, 2]).all()
    assert all(i < len(bodies[a].rods) and j < len(bodies[b].rods) for a, i, b, j in rows)
    kept = {tuple(r) for r in rows.tolist()}
    left_out = [(a, i, b, j) for a in range(len(bodies)) for b in range(a + 1, len(bodies))
                for i in range(len(bodies[a].rods)) for j in range(len(bodies[b].rods)) if (a, i, b, j) not in kept]
    assert all(_build_gap_cm(bodies, *pair) > REACH_MARGIN_CM for pair in left_out)
    # a spine of 12 segments can fold onto itself: segments 0 and 11 stay within reach
    assert (0, len(bodies) - 1) in {(a, b) for a, _, b, _ in kept} or len(bodies) < 12


def test_a_spec_file_robot_leaves_out_what_its_strings_hold_apart(tmp_path: Path):
    path = tmp_path / "hub.yaml"
    path.write_text(HUB_AND_FAR_ROD)
    rows, bodies = _pairs(load_morphology(str(path)))
    # hub 0 - far 1 and far 0 - hub 1 are out of reach; hub-hub and far-far are not
    assert sorted(map(tuple, rows.tolist())) == [(0, 0, 1, 0), (0, 1, 1, 1)]
    # MuJoCo is given exactly those pairs (with no collision filter in the way) and no other rod contacts
    terrain = build_terrain(SceneConfig(), 0.5, (0.0, 0.0))
    scene = MujocoPhysics(bodies, terrain, 1e-3, MujocoSettings(segment_contacts="reach"), rod_pairs=rows)
    model = scene.model
    assert model.npair == 2
    named = {(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g1), mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM,
                                                                                        g2))
             for g1, g2 in zip(model.pair_geom1, model.pair_geom2, strict=True)}
    assert named == {("s0r0", "s1r0"), ("s0r1", "s1r1")}
    scene.close()
    # and a trial of the file runs in it
    r = simulate(str(path), random_unit_params(load_morphology(str(path)), 1),
                 TrialConfig(duration_s=0.2, engine="mujoco", auto_dt=True,
                             engine_options={"segment_contacts": "reach"}), 1).result
    assert r.ok, r.reason


def test_reach_gives_the_bits_of_scene_while_no_segments_touch():
    morph = load_morphology("tetraspine")
    u = random_unit_params(morph, 1)
    runs = {mode: simulate(morph, u, TrialConfig(duration_s=1.0, engine="mujoco",
                                                 engine_options={"segment_contacts": mode}), 1).result
            for mode in ("scene", "reach")}
    assert runs["reach"].distance_m == runs["scene"].distance_m and runs["reach"].work_j == runs["scene"].work_j
    assert runs["reach"].distance_m != 0.0


def _contacts_of_stacked_segments(mode: str) -> dict[tuple[int, int], float]:
    """Segment 2 and 1 moved onto segment 0, high above the ground: {(body, body): summed normal force}."""
    morph = load_morphology("tetraspine-ntrt")
    rows, bodies = _pairs(morph)
    scene = MujocoPhysics(bodies, build_terrain(SceneConfig(), 0.5, (0, 0)), 1e-3,
                          MujocoSettings(segment_contacts=mode), rod_pairs=rows)
    scene.qpos[0][:3, :3] = bodies[0].com_cm + np.array([0.0, 100.0, 0.0])
    mujoco.mj_forward(scene.model, scene.data[0])
    data, force = scene.data[0], np.zeros(6)
    out: dict[tuple[int, int], float] = {}
    for n, c in enumerate(data.contact[:data.ncon]):
        key = tuple(sorted((int(scene.model.geom_bodyid[c.geom1]) - 1, int(scene.model.geom_bodyid[c.geom2]) - 1)))
        mujoco.mj_contactForce(scene.model, data, n, force)
        out[key] = out.get(key, 0.0) + force[0]
    scene.close()
    return out


def test_segments_pushed_together_push_back_in_reach_as_in_scene():
    scene, reach = _contacts_of_stacked_segments("scene"), _contacts_of_stacked_segments("reach")
    assert {(0, 1), (0, 2), (1, 2)} <= set(scene) and set(reach) == set(scene)
    for key, newton in scene.items():
        assert newton > 0.0 and reach[key] == pytest.approx(newton, rel=1e-9), (key, reach, scene)


def _distances(name: str, seeds: range, seconds: float) -> dict[str, list[float]]:
    morph = load_morphology(name)
    out: dict[str, list[float]] = {"scene": [], "reach": [], "twin": []}
    for seed in seeds:
        u = random_unit_params(morph, seed)
        for key, mode, jitter, s in (("scene", "scene", 0.0, seed), ("reach", "reach", 0.0, seed),
                                     ("twin", "scene", 1e-6, seed + 10_000)):
            cfg = TrialConfig(duration_s=seconds, engine="mujoco", pose_jitter_cm=jitter,
                              engine_options={"segment_contacts": mode})
            out[key].append(simulate(morph, u, cfg, s).result.distance_m)
    return out


def test_reach_moves_a_touching_spine_as_scene_does():
    """One short ribbed gait (ribs start 2 mm apart, so segment contacts form at once): the distance in
    "reach" is the one of "scene" within the chaos floor (a 1e-6 cm jittered twin)."""
    d = _distances("ribbed", range(1, 2), 0.2)
    chaos = rel(d["twin"][0], d["scene"][0], DISTANCE_FLOOR_M)
    assert rel(d["reach"][0], d["scene"][0], DISTANCE_FLOOR_M) <= max(chaos, 1e-9), d


@pytest.mark.slow
@pytest.mark.parametrize("name", ["octahedral-complex", "ribbed"])
def test_reach_distances_agree_with_scene_within_the_chaos_floor(name):
    """Five seeded 5 s gaits: the median distance difference between "reach" and "scene" is within the
    spine's chaos floor (median difference of 1e-6 cm jittered twins), or 1 % when that is smaller."""
    d = _distances(name, range(1, 6), 5.0)
    chaos = median(rel(t, s, DISTANCE_FLOOR_M) for t, s in zip(d["twin"], d["scene"], strict=True))
    diff = median(rel(r, s, DISTANCE_FLOOR_M) for r, s in zip(d["reach"], d["scene"], strict=True))
    assert diff <= max(chaos, 0.01), (diff, chaos, d)


def _hub_contacts(mode: str, tmp_path: Path) -> dict[tuple[str, str], tuple[float, ...]]:
    """The hub-and-far-rod robot's segment 1 pushed 9.6 cm toward segment 0, high above the ground (hubs and
    far rods overlap by 0.6 cm): {(geom, geom): (normal force N, friction, solref, solimp, margin)}."""
    path = tmp_path / "hub.yaml"
    path.write_text(HUB_AND_FAR_ROD)
    rows, bodies = _pairs(load_morphology(str(path)))
    scene = MujocoPhysics(bodies, build_terrain(SceneConfig(), 0.5, (0, 0)), 1e-3,
                          MujocoSettings(segment_contacts=mode, contact_geometry="capsules"), rod_pairs=rows)
    model, data = scene.model, scene.data[0]
    for b in range(2):
        data.qpos[7 * b + 1] += 100.0
    data.qpos[7 + 2] += 9.6
    mujoco.mj_forward(model, data)
    force, out = np.zeros(6), {}
    for n, c in enumerate(data.contact[:data.ncon]):
        if model.geom_bodyid[c.geom1] == 0 or model.geom_bodyid[c.geom2] == 0:
            continue
        mujoco.mj_contactForce(model, data, n, force)
        key = tuple(sorted((f"s{model.geom_bodyid[g] - 1}r{g - model.body_geomadr[model.geom_bodyid[g]]}")
                           for g in (c.geom1, c.geom2)))
        out[key] = (force[0], *c.friction, *c.solref, *c.solimp, c.includemargin)
    scene.close()
    return out


def test_explicit_pairs_push_back_as_the_search_does(tmp_path: Path):
    """Where reach gives explicit pairs (the hub-and-far-rod robot), their contacts carry the friction, solver
    settings and forces of the contacts MuJoCo's own search makes in scene."""
    scene, reach = _hub_contacts("scene", tmp_path), _hub_contacts("reach", tmp_path)
    assert set(scene) == {("s0r0", "s1r0"), ("s0r1", "s1r1")} == set(reach)
    for key, values in scene.items():
        assert values[0] > 0.0
        np.testing.assert_allclose(reach[key], values, rtol=1e-9, atol=1e-12)
