"""Run files are compressed: an 8-trial file of a 92-parameter robot is a small fraction of its old 2.5 MB; and a
live file does not grow at every flush."""

from __future__ import annotations

import h5py
import numpy as np

from spinefarm.storage.hdf5 import Hdf5Storage
from spinefarm.storage.hdf5_reader import read_run
from tests.storage_tests.conftest import make_meta, result


def test_an_eight_trial_file_is_small_and_reads_back_exactly(tmp_path):
    path = tmp_path / "r.h5"
    rng = np.random.default_rng(1)
    s = Hdf5Storage.create(path, make_meta("small", n_params=92))
    units = rng.random((8, 92))
    for i in range(8):
        s.add_trial(i, units[i], 2 * units[i] - 1, "monte_carlo", -1, i)
        s.finish_trial(i, result(i, float(i) / 10, seed=i), float(i) / 10)
    s.close()
    size = path.stat().st_size
    assert size < 250_000, size  # uncompressed, the same file took 2.5 MB (fixed 1024-row chunks)
    with h5py.File(path, "r") as f:
        assert all(f["trials"][name].compression == "gzip" for name in f["trials"])
    _, cols = read_run(path)
    np.testing.assert_array_equal(cols["params_unit"], units)
    assert cols["status"].tolist() == [b"complete"] * 8


def test_a_live_file_does_not_grow_with_every_flush_and_is_compressed_at_close(tmp_path):
    """A writer flushes after every result; the file it writes to grows with its rows, not its flushes (SWMR
    never reuses space: compressed chunks rewritten at every flush once made a 2,888-trial file 200 MB)."""
    path = tmp_path / "r.h5"
    rng = np.random.default_rng(2)
    s = Hdf5Storage.create(path, make_meta("live", n_params=20))
    sizes = {}
    for i in range(300):
        u = rng.random(20)
        s.add_trial(i, u, 2 * u - 1, "monte_carlo", -1, i)
        s.finish_trial(i, result(i, float(i) / 100, seed=i), float(i) / 100)
        s.flush()
        if i in (49, 299):
            sizes[i] = _hdf5_end(path)
    assert sizes[299] - sizes[49] < 64_000, sizes  # compressed live chunks: ~12 MB more
    s.close()
    with h5py.File(path, "r") as f:
        assert all(f["trials"][name].compression == "gzip" for name in f["trials"])
    assert path.stat().st_size < 200_000, path.stat().st_size
    _, cols = read_run(path)
    assert cols["status"].tolist() == [b"complete"] * 300
    assert cols["objective"].tolist() == [i / 100 for i in range(300)]
    resumed = Hdf5Storage.resume(path)  # a compressed file resumes as a live one, and compresses again
    resumed.close()
    _, again = read_run(path)
    np.testing.assert_array_equal(again["params_unit"], cols["params_unit"])


def _hdf5_end(path) -> int:
    """HDF5's end of file as its superblock states it (the writer keeps zeros reserved beyond it)."""
    from spinefarm.storage.probe import stored_eof

    with open(path, "rb") as fh:
        return stored_eof(fh.read(2048 + 48))
