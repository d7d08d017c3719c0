"""The HDF5 run file: self-describing, readable while written, crash-safe, resumable."""

from __future__ import annotations

import subprocess
import sys
import textwrap
import time

import h5py
import numpy as np
import pytest

from spinefarm.protocol.errors import StorageError
from spinefarm.storage.export import best_table, write_csv
from spinefarm.storage.hdf5 import Hdf5Storage
from spinefarm.storage.hdf5_reader import read_meta, read_run, snapshot
from tests.storage_tests.conftest import make_meta, result


def fill(storage, n: int, finished: int) -> None:
    for i in range(n):
        storage.add_trial(i, np.full(3, 0.5), np.zeros(3), "monte_carlo", -1, i)
    for i in range(finished):
        storage.finish_trial(i, result(i, float(i), seed=i), float(i))


def test_file_is_self_describing(tmp_path):
    path = tmp_path / "run.h5"
    with Hdf5Storage.create(path, make_meta()) as s:
        fill(s, 5, 3)
    with h5py.File(path, "r") as f:
        assert f.attrs["run_id"] == "run-a"
        assert "one row per trial" in f.attrs["description"]
        assert list(f.attrs["param_names"]) == ["p0", "p1", "p2"]
        assert list(f.attrs["param_units"]) == ["cm", "cm", "cm"]
        assert f["trials/distance_m"].attrs["unit"] == "m"
        assert f["trials/params"].shape == (5, 3)
        assert f["trials/status"][:].tolist() == [b"complete"] * 3 + [b"waiting"] * 2
        assert f["trials/distance_m"][2] == 2.0
    meta = read_meta(path)
    assert meta.morphology_spec == {"nodes": [1, 2]} and meta.settings.lease_s == 3.0  # typed, not a dict


def test_existing_file_is_not_overwritten(tmp_path):
    path = tmp_path / "run.h5"
    Hdf5Storage.create(path, make_meta()).close()
    with pytest.raises(StorageError, match="already exists"):
        Hdf5Storage.create(path, make_meta())


def test_reader_sees_flushed_rows_while_the_writer_runs(tmp_path):
    path = tmp_path / "run.h5"
    s = Hdf5Storage.create(path, make_meta())
    fill(s, 10, 4)
    s.flush()
    _, cols = read_run(path)
    assert len(cols["trial_id"]) == 10
    assert int(np.sum(cols["status"] == b"complete")) == 4
    s.finish_trial(7, result(7, 70.0, seed=7), 70.0)
    s.flush()
    assert Hdf5Storage.open_read(path).best_ids(1) == [7]
    n = snapshot(path, tmp_path / "snap.h5")  # consistent copy of a live file
    assert n == 10
    assert Hdf5Storage.open_read(tmp_path / "snap.h5").trial(7).distance_m == 70.0
    s.close()


def test_a_live_file_keeps_synced_room_to_grow_and_a_closed_one_is_trimmed(tmp_path):
    """While writing, the file holds written zeros beyond HDF5's end (a sync cut short by a dying disk
    then never leaves the file shorter than its header says); closed, it ends where its header says."""
    from spinefarm.storage.hdf5 import RESERVE_LOW_B
    from spinefarm.storage.probe import stored_eof

    path = tmp_path / "run.h5"
    s = Hdf5Storage.create(path, make_meta())
    done = 0
    for n in (1, 2000):  # also past the first chunk of rows
        for i in range(done, n):
            s.add_trial(i, np.full(3, 0.5), np.zeros(3), "monte_carlo", -1, i)
            s.finish_trial(i, result(i, float(i), seed=i), float(i))
        done = n
        s.flush()
        end = stored_eof(path.read_bytes()[:4096])
        assert path.stat().st_size - end >= RESERVE_LOW_B
        assert not any(path.read_bytes()[end:])  # the reserve is zeros, written
        assert len(read_run(path)[1]["trial_id"]) == n  # readers do not mind it
    s.close()
    assert path.stat().st_size == stored_eof(path.read_bytes()[:4096])
    assert len(read_run(path)[1]["trial_id"]) == 2000


def test_read_only_storage_refuses_writes(tmp_path):
    path = tmp_path / "run.h5"
    Hdf5Storage.create(path, make_meta()).close()
    ro = Hdf5Storage.open_read(path)
    with pytest.raises(StorageError, match="read-only"):
        ro.add_trial(0, np.zeros(3), np.zeros(3), "monte_carlo", -1, 0)


def test_not_a_run_file_is_a_clear_error(tmp_path):
    (tmp_path / "x.h5").write_bytes(b"not hdf5 at all")
    with pytest.raises(StorageError, match="cannot open"):
        read_run(tmp_path / "x.h5")
    with h5py.File(tmp_path / "y.h5", "w") as f:
        f.attrs["something"] = 1
    with pytest.raises(StorageError, match="not a spinefarm run file"):
        read_run(tmp_path / "y.h5")
    with pytest.raises(StorageError, match="does not exist"):
        read_run(tmp_path / "missing.h5")


WRITER = textwrap.dedent("""
    import sys, time, numpy as np
    sys.path.insert(0, {root!r})
    from tests.storage_tests.conftest import make_meta, result
    from spinefarm.storage.hdf5 import Hdf5Storage
    s = Hdf5Storage.create({path!r}, make_meta())
    for i in range(300):
        s.add_trial(i, np.full(3, 0.25), np.zeros(3), "monte_carlo", -1, i)
        if i % 2 == 0:
            s.finish_trial(i, result(i, float(i), seed=i), float(i))
    s.flush()
    print("flushed", flush=True)
    for i in range(300, 100000):  # keeps writing (unflushed) until killed
        s.add_trial(i, np.full(3, 0.25), np.zeros(3), "monte_carlo", -1, i)
        time.sleep(0.0001)
""")


def test_resume_after_sigkill_keeps_every_flushed_row(tmp_path):
    import pathlib

    root = str(pathlib.Path(__file__).resolve().parents[2])
    path = tmp_path / "run.h5"
    proc = subprocess.Popen([sys.executable, "-c", WRITER.format(root=root, path=str(path))],
                            stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "flushed"
    time.sleep(0.05)
    proc.kill()
    proc.wait()
    # The killed SWMR writer left its consistency flags: a plain read-write open is refused ...
    with pytest.raises(OSError), h5py.File(path, "r+"):
        pass
    # ... but readers get every flushed row, and resume clears the state by itself.
    _, cols = read_run(path)
    assert len(cols["trial_id"]) >= 300
    s = Hdf5Storage.resume(path)
    assert s.n_trials() >= 300
    assert s.counts()["complete"] == 150
    assert s.trial(298).distance_m == 298.0
    n = s.n_trials()
    s.add_trial(n, np.zeros(3), np.zeros(3), "gaussian", 298, 5)
    s.finish_trial(n, result(n, 1e6, seed=5), 1e6)
    s.close()
    with h5py.File(path, "r+") as f:  # closed cleanly: opens read-write again
        assert f["trials/distance_m"][n] == 1e6
    assert not (tmp_path / "run.h5.resume-tmp").exists()


def test_export_csv_and_best(tmp_path):
    import io

    path = tmp_path / "run.h5"
    with Hdf5Storage.create(path, make_meta()) as s:
        fill(s, 4, 3)
    ro = Hdf5Storage.open_read(path)
    buf = io.StringIO()
    write_csv(ro, buf)
    lines = buf.getvalue().splitlines()
    assert len(lines) == 5
    assert lines[0].split(",")[:2] == ["trial_id", "phase"] and lines[0].endswith("p0,p1,p2")
    table = best_table(ro, 2)
    assert table.splitlines()[1].split()[:2] == ["1", "2"]
    assert "p2 = 0 cm" in table


def test_the_best_table_shows_the_distance_each_set_ranks_by(tmp_path):
    # screened 0.3, 0.2, 0.1 m; the judge moved trial 0 to 0.05 m and held trial 2 at 0.1 m: by the distance
    # that counts the order is 1 (0.2, not judged), 2 (0.1, holds), 0 (0.05, moved)
    path = tmp_path / "run.h5"
    with Hdf5Storage.create(path, make_meta()) as s:
        for i, d in enumerate((0.3, 0.2, 0.1)):
            s.add_trial(i, np.full(3, 0.5), np.zeros(3), "monte_carlo", -1, i)
            s.finish_trial(i, result(i, d, seed=i), d)
        s.set_verification(0, "moved", 0.05, "moved 83% at the finer step")
        s.set_verification(2, "holds", 0.1)
    lines = best_table(Hdf5Storage.open_read(path), 3).splitlines()
    header = lines[0].split()
    rows = [dict(zip(header, ln.split(), strict=True)) for ln in lines[1:4]]
    assert [(r["trial"], r["counted_m"], r["verdict"]) for r in rows] == [
        ("1", "0.2", "-"), ("2", "0.1", "holds"), ("0", "0.05", "moved")]
    assert rows[2]["distance_m"] == "0.3"   # the screen's distance stays beside it


def test_resume_can_raise_the_budget_but_not_below_what_was_sampled(tmp_path):
    path = tmp_path / "run.h5"
    with Hdf5Storage.create(path, make_meta(budget=10)) as s:
        fill(s, 6, 6)
    with pytest.raises(StorageError, match="below the trials already sampled"):
        Hdf5Storage.resume(path, trials_budget=5)
    with Hdf5Storage.resume(path, trials_budget=50) as s:
        assert s.run_meta().trials_budget == 50 and s.n_trials() == 6
    assert read_meta(path).trials_budget == 50


def test_resume_budget_counts_parameter_sets_not_promoted_re_runs(tmp_path):
    """A multi-fidelity run of 6 parameter sets, 3 promoted once and 1 twice: 10 rows, budget in sets."""
    path = tmp_path / "run.h5"
    with Hdf5Storage.create(path, make_meta(budget=6)) as s:
        fill(s, 6, 6)
        for tid, parent, rung in ((6, 0, 1), (7, 1, 1), (8, 2, 1), (9, 6, 2)):
            s.add_trial(tid, np.full(3, 0.5), np.zeros(3), "promoted", parent, parent, rung=rung)
    with pytest.raises(StorageError, match="at least 6") as err:
        Hdf5Storage.resume(path, trials_budget=5)
    assert "received 5" in str(err.value)
    with Hdf5Storage.resume(path, trials_budget=8) as s:  # more sets than done, fewer than rows
        assert s.run_meta().trials_budget == 8 and s.n_trials() == 10


def test_lazy_reader_agrees_with_the_writer_on_a_live_file(tmp_path):
    from spinefarm.storage.hdf5_reader import Hdf5Reader

    path = tmp_path / "run.h5"
    s = Hdf5Storage.create(path, make_meta())
    fill(s, 12, 9)
    s.finish_trial(10, result(10, 4.5, seed=10), 4.5)
    s.flush()
    with Hdf5Reader(path) as r:
        assert r.n_trials() == 12 and r.counts() == s.counts()
        assert r.best_ids(4) == s.best_ids(4)
        assert r.trial(10) == s.trial(10) and r.best(2) == s.best(2)
        for ids in ([3, 4, 5], [11, 0, 7, 0], []):  # a run of rows, rows apart and repeated, none
            assert r.records(ids) == [s.trial(i) for i in ids]
        with pytest.raises(StorageError, match="no such trial"):
            r.records([2, 12])
        assert r.run_meta() == s.run_meta()
        with pytest.raises(StorageError, match="no such trial"):
            r.trial(12)
        with pytest.raises(StorageError, match="read-only"):
            r.add_trial(12, np.zeros(3), np.zeros(3), "monte_carlo", -1, 0)
    s.close()
    with pytest.raises(StorageError, match="does not exist"):
        Hdf5Reader(tmp_path / "nope.h5")


def _hold_open(path, seconds: float) -> subprocess.Popen:
    """Another process with the file open without SWMR (it holds HDF5's file lock), for `seconds`."""
    code = f"import h5py, time; f = h5py.File({str(path)!r}, 'r'); print('open', flush=True); time.sleep({seconds})"
    p = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "open"
    return p


def test_the_writer_waits_out_a_reader_holding_the_file_lock_and_names_one_that_keeps_it(tmp_path, monkeypatch):
    """A reader opening a run file (the API, a polling script) in the instant the writer opens it must not stop
    the search; a process that keeps the file open without SWMR gets a clear error, not a hang."""
    from spinefarm.storage import hdf5

    path = tmp_path / "r.h5"
    Hdf5Storage.create(path, make_meta()).close()
    holder = _hold_open(path, 0.8)
    t0 = time.monotonic()
    storage = Hdf5Storage._open_writer(path, make_meta(), hdf5.TrialTable(3), None)  # waits the lock out
    waited = time.monotonic() - t0
    storage.close()
    holder.wait(30)
    assert waited > 0.1
    monkeypatch.setattr(hdf5, "WRITER_LOCK_WAIT_S", 0.3)
    holder = _hold_open(path, 30)
    try:
        with pytest.raises(StorageError, match="another process holds it open without SWMR"):
            Hdf5Storage._open_writer(path, make_meta(), hdf5.TrialTable(3), None)
    finally:
        holder.kill()
        holder.wait(30)
