"""The figures the docs publish, each checked against its own derivation from a recorded trial: the cost of
transport (W / (m g d) by hand), the distance of the scored segment, the reel-in work, and a verification's
perturbed half. Each of these tests fails if the figure is computed wrongly (a dropped g, segment 0 scored
instead of the scored segment, the perturbed run ignored)."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.trial.simulation import random_unit_params, simulate

GAIT = Path(__file__).resolve().parents[2] / "examples" / "gaits" / "tetraspine.json"
G_M_S2 = 9.81


def _segments_by_hand(morph) -> tuple[np.ndarray, np.ndarray]:
    """(masses (n_seg,) kg, build-pose COMs (n_seg, 3) cm) from the rods: solid cylinders pi r^2 L rho."""
    spec = morph.structure
    nodes = np.asarray(spec.nodes, dtype=float)
    mass = np.zeros(spec.n_segments)
    moment = np.zeros((spec.n_segments, 3))
    for rod in spec.rods:
        mat = spec.rod_material(rod.tag)
        a, b = nodes[rod.a], nodes[rod.b]
        m = math.pi * mat.radius_cm ** 2 * math.dist(a, b) * mat.density_kg_per_cm3
        seg = spec.node_segment[rod.a]
        mass[seg] += m
        moment[seg] += m * (a + b) / 2
    return mass, moment / mass[:, None]


@pytest.fixture(scope="module")
def recorded():
    spec = json.loads(GAIT.read_text())
    morph = load_morphology(spec["morphology"])
    cfg = TrialConfig(duration_s=0.6, controller=spec["controller"], dt_s=1e-3, record_every_s=1e-3)
    return morph, simulate(morph, spec["params"], cfg, seed=0)


def test_distances_are_those_of_the_recorded_poses_and_the_scored_segment(recorded):
    morph, out = recorded
    r, poses = out.result, out.trajectory.arrays()["poses"]
    mass, build = _segments_by_hand(morph)
    seg = morph.scored_segment
    assert seg != 0
    end = poses[-1][:, :3]
    ntrt = math.hypot(end[seg, 0] - build[seg, 0], end[seg, 2] - build[seg, 2])
    seg0 = math.hypot(end[0, 0] - build[0, 0], end[0, 2] - build[0, 2])
    assert abs(ntrt - seg0) > 1e-3 * ntrt  # segment 0 would give another figure
    assert r.ntrt_distance_cm == pytest.approx(ntrt, rel=1e-9)
    com0 = (build * mass[:, None]).sum(axis=0) / mass.sum()
    com1 = (end * mass[:, None]).sum(axis=0) / mass.sum()
    distance_m = math.hypot(com1[0] - com0[0], com1[2] - com0[2]) / 100.0
    assert r.distance_m == pytest.approx(distance_m, rel=1e-9)
    assert r.speed_cm_s == pytest.approx(distance_m * 100.0 / 0.6, rel=1e-9)
    assert r.mass_kg == pytest.approx(mass.sum(), rel=1e-12)


def test_cot_is_work_over_m_g_d_by_hand(recorded):
    morph, out = recorded
    r = out.result
    mass, build = _segments_by_hand(morph)
    end = out.trajectory.arrays()["poses"][-1][:, :3]
    com0 = (build * mass[:, None]).sum(axis=0) / mass.sum()
    com1 = (end * mass[:, None]).sum(axis=0) / mass.sum()
    d_m = math.hypot(com1[0] - com0[0], com1[2] - com0[2]) / 100.0
    assert d_m > 0.005 and r.work_j > 0.1
    assert r.cot == pytest.approx(r.work_j / (mass.sum() * G_M_S2 * d_m), rel=1e-9)


def test_work_is_tension_times_shortening_by_hand(recorded):
    """The paper's III-D: the tension of every string times the length it was shortened by, every step;
    lengthening is free. From the recorded tension (after the step) and rest lengths at every step; the
    kernel uses the tension before the step, which differs by k * shortening^2 per step (under 1 %)."""
    morph, out = recorded
    a = out.trajectory.arrays()
    rest = a["rest_length_cm"]
    k = np.array([morph.structure.string_material(s.tag).stiffness_n_per_m for s in morph.structure.strings])
    shortening = np.maximum(0.0, rest[:-1] - rest[1:])  # cm, from step n to n+1
    # tension before step n+1's shortening: the recorded one plus k * (the shortening) where the string is taut
    tension_before_n = a["tension_n"][1:] + np.where(a["tension_n"][1:] > 0, k / 100.0 * shortening, 0.0)
    work_j = float((tension_before_n * shortening).sum()) * 0.01  # N cm -> J
    paper_j = float((a["tension_n"][1:] * shortening).sum()) * 0.01
    assert out.result.work_j == pytest.approx(work_j, rel=0.02)
    assert out.result.work_j == pytest.approx(paper_j, rel=0.02)


def test_the_judge_runs_and_counts_its_perturbed_half():
    """--verify-perturb: a judge task with perturb runs the perturbed trial (start pose jittered 0.01 cm, friction
    +10 %), returns its distance, and the verdict counts it. The stored distance is the judge's own, so only the
    perturbed half can fail it."""
    from spinefarm.protocol.settings import TaskFidelity
    from spinefarm.protocol.states import Verification
    from spinefarm.protocol.verdicts import judge_verdict
    from spinefarm.protocol.work import TrialAssignment
    from spinefarm.worker.service.assignment import physics_evaluator

    morph = load_morphology("tetraspine-ntrt")
    u = random_unit_params(morph, 4)
    cfg = TrialConfig(duration_s=1.0)
    fine = dataclasses.replace(cfg, dt_s=cfg.step_s / 4)
    pert = dataclasses.replace(fine, pose_jitter_cm=0.01, ground_friction=morph.ground_friction * 1.1)
    d_fine, d_pert = simulate(morph, u, fine, 4).result.distance_m, simulate(morph, u, pert, 4).result.distance_m
    change = abs(d_pert - d_fine) / d_fine
    assert change > 1e-3
    evaluate = physics_evaluator(morph, cfg, None)
    task = TrialAssignment(trial_id=0, lease_id=1, params_unit=tuple(u), seed=4, lease_s=60.0,
                           fidelity=TaskFidelity(task="judge", dt_s=fine.dt_s, perturb=True))
    r = evaluate(task)
    assert r.distance_m == d_fine and r.extras["perturbed_distance_m"] == d_pert
    holds, why = judge_verdict(d_fine, False, "bullet", r, tolerance=change * 2)
    assert holds == Verification.HOLDS and why == ""
    fails, why = judge_verdict(d_fine, False, "bullet", r, tolerance=change / 2)
    assert fails == Verification.MOVED and " in the perturbed run" in why and "at the finer step" not in why
    plain = evaluate(dataclasses.replace(task, fidelity=TaskFidelity(task="judge", dt_s=fine.dt_s)))
    assert "perturbed_distance_m" not in plain.extras


def test_verify_perturb_reaches_the_stored_judge_policy(tmp_path):
    """`search --verify-perturb` stores the judge policy the run's judge tasks are issued with."""
    import subprocess
    import sys

    from spinefarm.storage.hdf5 import Hdf5Storage

    policies = {}
    for flag in ("--verify-perturb", None):
        out = tmp_path / f"{flag or 'plain'}.h5"
        args = ["search", "sphere:3", "--trials", "4", "--workers", "1", "--api-port", "-1", "--out", str(out)]
        r = subprocess.run([sys.executable, "-m", "spinefarm", *args, *([flag] if flag else [])],
                           capture_output=True, text=True, timeout=120)
        assert r.returncode == 0, r.stderr
        store = Hdf5Storage.open_read(out)
        try:
            policies[flag] = store.run_meta().settings.judge
        finally:
            store.close()
    assert policies["--verify-perturb"].perturb and not policies[None].perturb
