"""The kinds of evaluation (judge, audit, referee, opinion) are spelled once, protocol.states.EvaluationKind: the
ladder's lease keys, the tasks a worker is given and the stored rows all use it, and a row of any other kind is
refused in one line naming it and the known kinds, with nothing stored."""

from __future__ import annotations

import re
from pathlib import Path

import h5py
import pytest

from spinefarm.coordinator.ladder.keys import KINDS, TRIAL, check_key, split_key
from spinefarm.protocol.errors import StorageError
from spinefarm.protocol.settings import TASKS, TaskFidelity
from spinefarm.protocol.states import EvaluationKind
from spinefarm.storage.evaluations import row_of
from spinefarm.storage.hdf5 import Hdf5Storage
from tests.storage_tests.conftest import make_meta, result

ROOT = Path(__file__).resolve().parents[2]
KNOWN = "one of judge, audit, referee, opinion"   # the paper's checks, as docs/distributed.md names them


def _run(path: Path) -> Hdf5Storage:
    s = Hdf5Storage.create(path, make_meta("run-k"))
    s.add_trial(0, [0.5] * 3, [0.0] * 3, "monte_carlo", -1, 0)
    s.finish_trial(0, result(0, 0.3), 0.3)
    return s


@pytest.mark.parametrize("kind", ["verify", "Judge", "", b"opinion\xff"])
def test_a_row_of_an_unknown_kind_is_refused_in_one_line_naming_it_and_the_known_kinds(kind):
    with pytest.raises(StorageError) as err:
        row_of(0, kind, result(0, 0.3), "bullet", 2.5e-4)
    message = str(err.value)
    assert "\n" not in message and repr(kind) in message and KNOWN in message, message


def test_a_stored_row_of_an_unknown_kind_is_refused_and_loses_nothing(tmp_path):
    s = _run(tmp_path / "k.h5")
    try:
        s.add_evaluation(row_of(0, "judge", result(0, 0.31), "bullet", 2.5e-4, "w-2"))
        forged = {**row_of(0, "audit", result(0, 0.29), "", None, "w-3"), "kind": b"recheck"}
        with pytest.raises(StorageError, match=f"unknown evaluation kind; received b'recheck'; expected {KNOWN}"):
            s.add_evaluation(forged)
        s.add_evaluation(row_of(0, "opinion", result(0, 0.33), "mujoco", 1e-3, "w-4"))
    finally:
        s.close()
    with h5py.File(tmp_path / "k.h5", "r") as f:
        assert f["evaluations/kind"][:].tolist() == [b"judge", b"opinion"]
        assert f["evaluations/distance_m"][:].tolist() == [0.31, 0.33]


def test_lease_keys_and_tasks_name_the_same_kinds():
    assert set(KINDS.values()) == set(EvaluationKind)
    for code, kind in KINDS.items():
        assert split_key(check_key(code, 5)) == (kind, 5)
    assert split_key(7) == (TRIAL, 7)
    # a referee re-runs a disputed row as an audit does: the tasks are the screen's and three kinds
    assert set(TASKS) == {"trial", "judge", "audit", "opinion"}
    for task in TASKS:
        assert TaskFidelity(task).task == task


def test_no_module_spells_a_stored_kind_of_its_own():
    """A stored kind is compared as EvaluationKind.X.stored, never as a byte string of its own."""
    pattern = re.compile(r"""b["'](judge|audit|referee|opinion)["']""")
    found = [f"{p.relative_to(ROOT)}:{i}" for p in (ROOT / "spinefarm").rglob("*.py")
             for i, line in enumerate(p.read_text().splitlines(), 1) if pattern.search(line)]
    assert found == []


def test_a_file_holding_an_unknown_kind_is_not_resumed_and_stays_as_it_was(tmp_path):
    path = tmp_path / "k.h5"
    s = _run(path)
    s.add_evaluation(row_of(0, "judge", result(0, 0.31), "bullet", 2.5e-4, "w-2"))
    s.add_evaluation(row_of(0, "audit", result(0, 0.29), "", None, "w-3"))
    s.close()
    with h5py.File(path, "r+") as f:   # a foreign writer's row
        f["evaluations/kind"][1] = b"recheck"
    before = path.read_bytes()
    with pytest.raises(StorageError) as err:
        Hdf5Storage.resume(path)
    assert str(err.value) == (f"cannot resume {path}: evaluation row 1 of 2 has an unknown kind; "
                              f"received b'recheck'; expected {KNOWN}")
    assert path.read_bytes() == before
