"""What differs between two environment records, by hand: a package on one side only is named with "missing",
the model path's packages first in their fixed order, then the others by name; one message joins the lines
(protocol.environment)."""

from __future__ import annotations

from spinefarm.protocol.environment import describe_differences, differences


def _rec(packages: dict[str, str]) -> dict:
    return {"spinefarm_version": "1", "spinefarm_commit": "abc", "python": "3.11.7", "packages": packages,
            "cpu_model": "CPU", "env": {}}


def test_packages_on_one_side_only_are_named_model_packages_first() -> None:
    recorded = _rec({"numpy": "1.0", "pybullet": "3.2", "zeta": "1", "same": "5"})
    here = _rec({"numpy": "2.0", "mujoco": "3.1", "alpha": "2", "same": "5"})
    expected = ["numpy 2.0 here, 1.0 in the run", "pybullet missing here, 3.2 in the run",
                "mujoco 3.1 here, missing in the run", "alpha 2 here, missing in the run",
                "zeta missing here, 1 in the run"]
    assert differences(recorded, here) == expected
    assert describe_differences(recorded, here) == "the environment differs from the run's: " + "; ".join(expected)
    assert describe_differences(recorded, recorded) == ""
