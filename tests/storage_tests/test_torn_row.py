"""A writer killed inside a flush never leaves a `complete` row without its data (a torn row).

One HDF5 flush writes every changed chunk, in an order HDF5 chooses; a process killed inside it keeps
whichever chunks were already written. The worst order writes the status column first: a row then says
`complete` while its distance and scores are still the fill value (NaN), and every `--resume` refuses
the file. The writer therefore flushes the rows' data before it writes their status.

The test puts a real writer process in that worst case on purpose: its status column is an h5py
dataset that, the moment the writer stores a status, flushes that one dataset to the file (H5Dflush:
its chunks and chunk index, nothing of the other columns) and SIGKILLs its own process. With the data
written after the status, or in the same flush, the file it leaves holds torn rows.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np

from spinefarm.storage.hdf5 import Hdf5Storage
from spinefarm.storage.hdf5_reader import read_run
from spinefarm.storage.validate import row_problems
from tests.storage_tests.conftest import result

ROOT = Path(__file__).resolve().parents[2]
STORED, KILLED_BATCH, WAITING = 10, 5, 5  # rows: acknowledged, in the flush that dies, never finished

WRITER = textwrap.dedent("""
    import os, signal, sys
    import h5py, numpy as np
    sys.path.insert(0, {root!r})
    from tests.storage_tests.conftest import make_meta, result
    from spinefarm.storage.hdf5 import Hdf5Storage

    class StatusFirstThenDie(h5py.Dataset):
        # The status reaches the file before anything else of this flush, then the process dies.
        def __setitem__(self, key, value):
            super().__setitem__(key, value)
            self.flush()
            os.kill(os.getpid(), signal.SIGKILL)

    s = Hdf5Storage.create({path!r}, make_meta())
    for i in range({total}):
        s.add_trial(i, np.full(3, 0.25), np.zeros(3), "monte_carlo", -1, i)
    for i in range({stored}):
        s.finish_trial(i, result(i, float(i + 1), seed=i), float(i + 1))
    s.flush()  # on return these rows are stored: a coordinator acknowledges them now
    print("stored", flush=True)
    for i in range({stored}, {stored} + {batch}):
        s.finish_trial(i, result(i, float(i + 1), seed=i), float(i + 1))
    s._datasets["status"] = StatusFirstThenDie(s._datasets["status"].id)
    s.flush()
    print("flush returned", flush=True)
""")


def test_a_writer_killed_right_after_its_status_write_leaves_no_torn_row(tmp_path):
    path = tmp_path / "run.h5"
    script = WRITER.format(root=str(ROOT), path=str(path), total=STORED + KILLED_BATCH + WAITING,
                           stored=STORED, batch=KILLED_BATCH)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    assert proc.stdout.split() == ["stored"]  # killed inside the second flush, not before or after it

    meta, cols = read_run(path)
    torn = [what for what, rows in row_problems(meta, cols).items() if rows.any()]
    assert torn == [], f"the killed writer left invalid rows: {torn}"
    # The kill came after the status reached the file (else the test proves nothing): the batch says
    # complete, so its data had to be there first.
    batch = slice(STORED, STORED + KILLED_BATCH)
    assert (cols["status"][batch] == b"complete").all()
    np.testing.assert_array_equal(cols["distance_m"][batch], np.arange(STORED, STORED + KILLED_BATCH) + 1.0)

    s = Hdf5Storage.resume(path)  # what `search --resume` opens the file with
    try:
        assert s.n_trials() == STORED + KILLED_BATCH + WAITING
        assert s.counts() == {"waiting": WAITING, "complete": STORED + KILLED_BATCH, "failed": 0}
        assert [s.trial(i).distance_m for i in range(STORED)] == [float(i + 1) for i in range(STORED)]
        for i in range(STORED + KILLED_BATCH, STORED + KILLED_BATCH + WAITING):  # the run goes on
            assert s.finish_trial(i, result(i, float(i + 1), seed=i), float(i + 1))
    finally:
        s.close()
    _, cols = read_run(path)
    assert (cols["status"] == b"complete").all()
