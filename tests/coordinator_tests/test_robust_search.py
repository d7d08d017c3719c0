"""A robust search as a user runs it: K randomised episodes per parameter set, every one stored, resumed exactly."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import numpy as np

import spinefarm
from spinefarm.api.app import create_app
from spinefarm.protocol.robust import RobustSpec
from spinefarm.robot.morphology.model import Morphology
from spinefarm.storage.hdf5_reader import Hdf5Reader, read_episodes, read_meta, read_run
from spinefarm.worker.trial.robust import run_episodes
from spinefarm.worker.trial.simulation import TrialConfig
from tests.coordinator_tests.procs import ROOT
from tests.http_server import served

RANDOMIZE = "friction=0.1,mass=0.05,start_jitter_cm=0.5"


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "spinefarm", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=300)


def test_episodes_are_stored_and_resumed_exactly(tmp_path):
    out = tmp_path / "robust.h5"
    r = run("search", "tetraspine", "--trials", "3", "--workers", "1", "--duration", "0.2", "--episodes", "2",
            "--randomize", RANDOMIZE, "--robust", "q25", "--no-verify", "--api-port", "-1", "--quiet",
            "--seed", "4", "--out", str(out), "--engine", "bullet")
    assert r.returncode == 0, r.stderr
    # the report names the objective as a statistic over the episodes, apart from the episodes' medians
    assert "(q25 of distance over 2 episodes) · medians: distance" in r.stdout + r.stderr
    meta = read_meta(out)
    assert meta.run["robust"] == {"episodes": 2, "randomize": {"friction": 0.1, "mass": 0.05,
                                                              "start_jitter_cm": 0.5}, "statistic": "q25"}
    before = read_episodes(out)
    assert sorted(zip(before["trial_id"].tolist(), before["episode"].tolist(), strict=True)) == \
        [(t, k) for t in range(3) for k in range(2)]

    r = run("search", "--resume", str(out), "--trials", "5", "--workers", "1", "--no-verify", "--api-port", "-1",
            "--quiet")
    assert r.returncode == 0, r.stderr
    after = read_episodes(out)
    assert len(after["trial_id"]) == 10
    first = np.isin(after["trial_id"], [0, 1, 2])
    for name, col in before.items():  # the episodes written before the resume, bit for bit
        assert np.array_equal(col, after[name][first], equal_nan=col.dtype.kind == "f"), name

    _, cols = read_run(out)
    spec = RobustSpec.from_dict(meta.run["robust"])
    morph = Morphology.from_dict(meta.morphology_spec)
    cfg = TrialConfig.from_dict(meta.trial_config)
    for tid in range(5):
        mine = after["trial_id"] == tid
        d = np.sort(after["distance_m"][mine])
        assert cols["objective"][tid] == d[0] + 0.25 * (d[1] - d[0])  # q25 of two values, by hand
        assert cols["distance_m"][tid] == (d[0] + d[1]) / 2  # the row holds the median
    # a stored trial re-run here gives the stored episodes' bits (the same worlds from the trial's seed)
    again = run_episodes(morph, cols["params_unit"][4], cfg, int(cols["seed"][4]), spec, controller=meta.controller)
    mine = np.flatnonzero(after["trial_id"] == 4)
    assert [e.distance_m for e in again.episodes] == after["distance_m"][mine].tolist()
    assert [e.friction_scale for e in again.episodes] == after["friction_scale"][mine].tolist()

    eps = spinefarm.load_run(out, episodes=True)
    assert list(eps.index.names) == ["trial_id", "episode"] and len(eps) == 10
    assert eps.loc[(4, 1), "distance_m"] == after["distance_m"][mine[1]]
    with Hdf5Reader(out) as reader:
        assert reader.episodes(2)["episode"].tolist() == [0, 1]
    assert len(spinefarm.load_run(out)) == 5

    with served(create_app([out])) as client:  # the API gives each trial's episodes and spread
        body = client.get(f"/runs/{meta.run_id}/trials/4/episodes").json()
        assert body["robust"]["statistic"] == "q25" and [e["episode"] for e in body["episodes"]] == [0, 1]
        assert [e["distance_m"] for e in body["episodes"]] == after["distance_m"][mine].tolist()
        speeds = after["speed_cm_s"][mine]
        assert body["spread"]["speed_cm_s"]["median"] == np.median(speeds)
        assert body["spread"]["speed_cm_s"]["min"] == speeds.min()
        missing = client.get(f"/runs/{meta.run_id}/trials/99/episodes")
        assert missing.status_code == 404 and "no such trial" in missing.json()["detail"]["message"]


def test_a_robust_best_is_judged_over_all_its_worlds_at_a_finer_step(tmp_path):
    out = tmp_path / "verified.h5"
    r = run("search", "tetraspine", "--trials", "2", "--workers", "1", "--duration", "0.3", "--episodes", "3",
            "--randomize", RANDOMIZE, "--verify-tolerance", "0.5", "--api-port", "-1", "--quiet", "--out", str(out),
            "--engine", "bullet")
    assert r.returncode == 0, r.stderr
    meta, cols = read_run(out)
    best = int(np.flatnonzero(cols["verification"] != b"")[0])
    assert cols["verification"][best] == b"holds", cols["verify_reason"][best]
    # the judge re-ran the same 3 worlds at the finer step: its distance is their median there
    cfg = TrialConfig.from_dict(meta.trial_config)
    fine = run_episodes(Morphology.from_dict(meta.morphology_spec), cols["params_unit"][best],
                        dataclasses.replace(cfg, dt_s=cfg.step_s / 4, auto_dt=False), int(cols["seed"][best]),
                        RobustSpec.from_dict(meta.run["robust"]), controller=meta.controller)
    assert cols["verify_distance_m"][best] == fine.distance_m
    assert cols["verify_distance_m"][best] != cols["distance_m"][best]


def test_with_rungs_each_rung_runs_its_own_number_of_episodes(tmp_path):
    out = tmp_path / "rungs.h5"
    r = run("search", "tetraspine", "--trials", "4", "--workers", "1", "--rungs", "0.2,0.4", "--eta", "2",
            "--episodes", "1,3", "--randomize", RANDOMIZE, "--no-verify", "--api-port", "-1", "--quiet",
            "--out", str(out), "--engine", "bullet")
    assert r.returncode == 0, r.stderr
    _, cols = read_run(out)
    eps = read_episodes(out)
    counts = {int(t): int(np.count_nonzero(eps["trial_id"] == t)) for t in cols["trial_id"]}
    assert {counts[t] for t in counts if cols["rung"][t] == 0} == {1}
    promoted = [t for t in counts if cols["rung"][t] == 1]
    assert promoted and {counts[t] for t in promoted} == {3}
