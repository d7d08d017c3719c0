"""Heavy imports stay at the edges: each module is imported in a clean interpreter."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

HEAVY = ("pybullet", "zenoh", "h5py", "fastapi", "numba", "mujoco")
ALLOWED = {
    "spinefarm.protocol.params": set(),
    "spinefarm.protocol.envelope": set(),
    "spinefarm.protocol.results": set(),
    "spinefarm.protocol.work": set(),
    "spinefarm.protocol.errors": set(),
    "spinefarm.robot.morphology.registry": set(),
    "spinefarm.worker.trial.simulation": {"numba"},
    "spinefarm.worker.engines.bullet": {"pybullet", "numba"},
    "spinefarm.worker.engines.mujoco": {"mujoco"},
    "spinefarm.worker.trial.setup": {"numba"},
    "spinefarm.storage.hdf5": {"h5py"},
}


@pytest.mark.parametrize("module", sorted(ALLOWED))
def test_module_imports_only_what_it_may(module):
    code = (f"import sys, json; import {module}; "
            f"print(json.dumps([m for m in {list(HEAVY)!r} if m in sys.modules]))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    loaded = set(json.loads(out.stdout.strip().splitlines()[-1]))
    assert loaded <= ALLOWED[module], f"{module} pulled in {sorted(loaded - ALLOWED[module])}"
