"""Heavy imports stay at the edges: zenoh only in */service.py, h5py only in spinefarm/storage/, no pybullet here."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
OWN = [*(f"spinefarm/{p}" for p in (
    "protocol/keys.py", "protocol/envelope.py", "protocol/work.py", "protocol/submissions.py", "coordinator", "storage",
    "api", "cli/service_commands.py", "cli/search_loop.py", "cli/run_setup.py", "cli/search_args.py", "cli/report.py",
    "cli/export_command.py", "worker/service/zenoh_worker.py")), "bench/coordinator_throughput.py"]


def loaded_after(statement: str) -> set[str]:
    code = f"import sys; {statement}; print(' '.join(sorted(m.split('.')[0] for m in sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    return set(out.stdout.split())


@pytest.mark.parametrize(("statement", "forbidden"), [
    ("import spinefarm.protocol.keys, spinefarm.protocol.work, spinefarm.protocol.submissions",
     {"zenoh", "h5py", "pybullet", "fastapi"}),
    ("import spinefarm.coordinator.core, spinefarm.coordinator.setup, spinefarm.coordinator.samplers, "
     "spinefarm.coordinator.problem",
     {"zenoh", "h5py", "pybullet", "mujoco", "numba", "fastapi"}),
    ("import spinefarm.coordinator.service, spinefarm.cli.search_loop, spinefarm.cli.run_setup",
     {"pybullet", "mujoco", "numba"}),
    ("import spinefarm.storage", {"h5py", "zenoh", "pybullet"}),
    ("import spinefarm.api.app", {"zenoh", "pybullet"}),
    ("import spinefarm.cli.service_commands", {"zenoh", "h5py", "pybullet", "mujoco", "numba", "fastapi"}),
])
def test_clean_interpreter_imports_stay_light(statement, forbidden):
    assert not loaded_after(statement) & forbidden


def test_heavy_import_statements_live_only_at_the_edges():
    files = [p for own in OWN for p in ((ROOT / own).rglob("*.py") if (ROOT / own).is_dir() else [ROOT / own])]
    assert len(files) > 20
    for path in files:
        rel = path.relative_to(ROOT).as_posix()
        text = path.read_text()
        if re.search(r"^\s*(import|from) zenoh\b", text, re.M):
            assert rel.endswith(("/service.py", "/zenoh_worker.py")), rel
        if re.search(r"^\s*(import|from) h5py\b", text, re.M):
            assert rel.startswith("spinefarm/storage/"), rel
        assert not re.search(r"^\s*(import|from) pybullet\b", text, re.M), rel


def test_service_extras_keep_the_api_free_of_simulators():
    import tomllib

    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    names = {k: {re.split(r"[<>=\[ ]", d)[0].lower() for d in v} for k, v in extras.items()}
    assert {"worker", "coordinator", "api", "all"} <= set(names)
    assert not names["api"] & {"pybullet", "numba", "mujoco", "eclipse-zenoh"}
    assert {"pybullet", "numba"} <= names["worker"]
    assert {"h5py", "eclipse-zenoh"} <= names["coordinator"]
