"""A check's evaluation row says where its run went (docs/distributed.md: `engine` and `dt_s` of each row): a
result that names no engine or step gets its task's, an audit's being the row's own."""

from __future__ import annotations

from tests.coordinator_tests.test_check_rules import _audited
from tests.storage_tests.conftest import result


def test_an_audit_whose_result_names_no_engine_is_stored_with_the_engine_and_step_the_row_ran_at(tmp_path):
    storage, checks = _audited(tmp_path / "r.h5")
    for tid, distance_m in ((0, 0.111), (2, 0.05), (1, 0.213)):   # MuJoCo at 2 ms, Bullet at 1 ms, neither stored
        assert result(tid, distance_m).extras == {}
        checks.settle_audit(tid, result(tid, distance_m), "w-d", exact=True)
    ev = storage.evaluations()
    assert ev["engine"].tolist() == [b"mujoco", b"bullet", b""]
    assert ev["dt_s"][:2].tolist() == [0.002, 0.001]
    storage.close()
