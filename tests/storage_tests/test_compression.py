"""Run files are compressed: an 8-trial file of a 92-parameter robot is a small fraction of its old 2.5 MB."""

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
