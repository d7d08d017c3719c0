"""A real search (`spinefarm search`: embedded Zenoh, two local worker processes, an HDF5 run file) whose promotions go
on from the kept ends of their last rungs: every promoted row holds the bits of the same trial simulated from the
start in this process, and a row went on only on the worker that ran its last rung; `--no-continue` simulates every
promotion from the start, with the same bits."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import pytest

from spinefarm.protocol.run import RunConfig
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.storage.hdf5_reader import read_run
from spinefarm.worker.trial.simulation import simulate
from tests.coordinator_tests.procs import ROOT

SEARCH = ["tetraspine", "--controller", "sidewinding", "--engine", "mujoco", "--dt", "0.002", "--engine-option",
          "segment_contacts=off", "--rungs", "0.5,1.5", "--duration", "1.5", "--eta", "2", "--settle", "0.2",
          "--trials", "10", "--workers", "2", "--sampler", "random", "--seed", "3", "--no-verify", "--api-port", "-1",
          "--quiet"]


def _search(tmp_path, name: str, *extra: str) -> tuple[RunConfig, dict]:
    out = tmp_path / f"{name}.h5"
    proc = subprocess.run([sys.executable, "-m", "spinefarm", "search", *SEARCH, "--out", str(out), *extra],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    meta, cols = read_run(out)
    return RunConfig.from_dict(meta.run), cols


def _promoted(cols: dict) -> list[int]:
    done = (cols["phase"] == b"promoted") & (cols["status"] == b"complete")
    return [int(i) for i in done.nonzero()[0]]


def _same_as_from_the_start(config: RunConfig, cols: dict, rows: list[int]) -> None:
    cfg = TrialConfig.from_dict(config.trial_config)
    for i in rows:
        fresh = simulate(config.morphology_spec, cols["params_unit"][i], dataclasses.replace(
            cfg, duration_s=float(cols["duration_s"][i])), int(cols["seed"][i]), controller="sidewinding").result
        for name in ("distance_m", "ntrt_distance_cm", "work_j", "cot", "sim_time_s"):
            assert cols[name][i] == getattr(fresh, name), (i, name)


def test_promotions_continue_on_the_worker_that_ran_their_rung_with_the_bits_of_a_run_from_the_start(tmp_path):
    config, cols = _search(tmp_path, "on")
    promoted = _promoted(cols)
    assert len(promoted) >= 3
    continued = cols["continued_s"]
    for i in promoted:
        parent = int(cols["parent"][i])
        if continued[i] > 0:   # only the worker that ran the rung kept its end: settle and rung, to the step
            assert cols["worker_id"][i] == cols["worker_id"][parent]
            assert continued[i] == pytest.approx(0.2 + 0.5, abs=1e-12)
        else:
            assert continued[i] == 0.0
    assert (continued[promoted] > 0).any()
    _same_as_from_the_start(config, cols, promoted)


def test_with_no_continue_every_promotion_is_simulated_from_the_start(tmp_path):
    config, cols = _search(tmp_path, "off", "--no-continue")
    promoted = _promoted(cols)
    assert len(promoted) >= 3 and not (cols["continued_s"] > 0).any()
    _same_as_from_the_start(config, cols, promoted)


def test_a_promotion_of_a_rung_run_before_a_restart_is_simulated_from_the_start_with_the_same_bits(tmp_path):
    """One worker screens four sets; the search is resumed to six with a new worker, which promotes a set the first
    one screened (seed 4: row 1, third of the first four, makes the top half of six). The new worker has no end
    of it: it simulates from the start, with the same bits; its own sets' promotions go on from their ends."""
    out = tmp_path / "run.h5"
    one = list(SEARCH)
    for flag, value in (("--seed", "4"), ("--trials", "4"), ("--workers", "1")):
        one[one.index(flag) + 1] = value
    for argv in (["search", *one, "--out", str(out)],
                 ["search", "--resume", str(out), "--trials", "6", "--workers", "1", "--api-port", "-1", "--quiet"]):
        proc = subprocess.run([sys.executable, "-m", "spinefarm", *argv], cwd=ROOT, capture_output=True, text=True,
                              timeout=300)
        assert proc.returncode == 0, proc.stderr[-2000:]
    meta, cols = read_run(out)
    promoted = _promoted(cols)
    elsewhere = [i for i in promoted if cols["worker_id"][i] != cols["worker_id"][int(cols["parent"][i])]]
    assert elsewhere and all(cols["continued_s"][i] == 0.0 for i in elsewhere)
    assert all(cols["continued_s"][i] > 0 for i in promoted if i not in elsewhere)
    _same_as_from_the_start(RunConfig.from_dict(meta.run), cols, promoted)


def test_a_users_spec_file_continues_as_a_built_in_does(tmp_path):
    """A robot from the user's own file (the Tetraspine written out, its ground friction changed so it is no built-in
    in disguise): its promotions go on from their rungs' ends with the bits of a run from the start."""
    spec = subprocess.run([sys.executable, "-m", "spinefarm", "spec", "tetraspine", "--name", "my-spine"], cwd=ROOT,
                          capture_output=True, text=True, timeout=60, check=True).stdout
    assert "ground_friction: 0.5" in spec
    path = tmp_path / "my-spine.yaml"
    path.write_text(spec.replace("ground_friction: 0.5", "ground_friction: 0.7"))
    out = tmp_path / "mine.h5"
    argv = [str(path), *SEARCH[1:], "--out", str(out)]
    proc = subprocess.run([sys.executable, "-m", "spinefarm", "search", *argv], cwd=ROOT, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    meta, cols = read_run(out)
    config = RunConfig.from_dict(meta.run)
    assert config.morphology == "my-spine" and config.morphology_spec["ground_friction"] == 0.7
    promoted = _promoted(cols)
    assert len(promoted) >= 3 and (cols["continued_s"][promoted] > 0).any()
    _same_as_from_the_start(config, cols, promoted)
