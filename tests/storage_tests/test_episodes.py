"""The episodes table, in every storage: rows of a trial's episodes, stored once with the trial, read back
exactly; in a run file also by readers, after a resume, and never for a trial whose result was not stored."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from spinefarm.protocol.robust import EpisodeResult
from spinefarm.storage.episodes import EPISODE_NAMES
from spinefarm.storage.hdf5 import Hdf5Storage
from spinefarm.storage.hdf5_reader import Hdf5Reader, read_episodes
from tests.storage_tests.conftest import make_meta, result


def episodes(trial_id: int, k: int) -> tuple[EpisodeResult, ...]:
    return tuple(EpisodeResult(e, 1000 * trial_id + e, "complete" if e else "failed", "" if e else "diverged: x",
                               0.1 * trial_id + 0.01 * e, 1.0, 2.0 + e, 3.0, 4.0, 5.0, 0.5, 1.0 + 0.01 * e,
                               1.0 - 0.01 * e, 0.5, -1) for e in range(k))


def finish(storage, tid: int, k: int) -> None:
    u = np.full(3, 0.5)
    storage.add_trial(tid, u, u, "monte_carlo", -1, tid)
    assert storage.finish_trial(tid, dataclasses.replace(result(tid, 0.1 * tid, seed=tid), episodes=episodes(tid, k)),
                                0.1 * tid)


def test_each_trials_episodes_come_back_in_order_and_exactly(storage):
    finish(storage, 0, 3)
    finish(storage, 1, 2)
    storage.flush()
    mine = storage.episodes(1)
    assert mine["episode"].tolist() == [0, 1]
    assert mine["seed"].tolist() == [1000, 1001]
    assert mine["status"].tolist() == [b"failed", b"complete"]
    assert mine["speed_cm_s"].tolist() == [2.0, 3.0] and mine["mass_scale"].tolist() == [1.0, 0.99]
    assert len(storage.episodes()["trial_id"]) == 5
    # a result stored twice is refused, and so are its episodes
    assert not storage.finish_trial(1, dataclasses.replace(result(1, 0.1), episodes=episodes(1, 2)), 0.1)
    assert len(storage.episodes()["trial_id"]) == 5


def test_a_plain_runs_episodes_are_empty(storage):
    u = np.full(3, 0.5)
    storage.add_trial(0, u, u, "monte_carlo", -1, 0)
    storage.finish_trial(0, result(0, 0.1), 0.1)
    assert set(storage.episodes()) == set(EPISODE_NAMES) and len(storage.episodes()["trial_id"]) == 0


def test_a_run_file_keeps_its_episodes_for_readers_and_through_a_resume(tmp_path):
    path = tmp_path / "r.h5"
    s = Hdf5Storage.create(path, make_meta())
    for tid in range(3):
        finish(s, tid, 4)
    s.flush()
    live = read_episodes(path)  # a reader beside the live writer
    assert len(live["trial_id"]) == 12
    with Hdf5Reader(path) as reader:
        assert reader.episodes(2)["distance_m"].tolist() == pytest.approx([0.2, 0.21, 0.22, 0.23])
    s.close()
    s = Hdf5Storage.resume(path, trials_budget=200)
    finish(s, 3, 2)
    s.close()
    after = read_episodes(path)
    for name in EPISODE_NAMES:
        assert np.array_equal(after[name][:12], live[name], equal_nan=after[name].dtype.kind == "f"), name
    assert after["trial_id"][12:].tolist() == [3, 3]


def test_episodes_of_a_trial_never_stored_as_finished_are_dropped(tmp_path):
    """A writer killed between a trial's episodes and its status: the trial runs again after the resume."""
    import h5py

    path = tmp_path / "r.h5"
    s = Hdf5Storage.create(path, make_meta())
    finish(s, 0, 2)
    s.add_trial(1, np.full(3, 0.5), np.full(3, 0.5), "monte_carlo", -1, 1)
    s.close()
    with h5py.File(path, "r+") as f:  # what the killed writer left: trial 1's episodes, its status still waiting
        g = f["episodes"]
        for name in EPISODE_NAMES:
            g[name].resize(3, axis=0)
            g[name][2] = g[name][1]
        g["trial_id"][2] = 1
    assert read_episodes(path)["trial_id"].tolist() == [0, 0]
    s = Hdf5Storage.resume(path)
    assert s.episodes()["trial_id"].tolist() == [0, 0]
    s.close()
