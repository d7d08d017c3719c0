"""A run is data: robots from spec files are searched across real workers, the run's spec is the
authority, and a worker or local process that cannot serve a run stops the search with its reason."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from spinefarm.protocol.errors import ConfigError
from spinefarm.storage.hdf5 import Hdf5Storage
from tests.coordinator_tests.helpers import wait_for
from tests.coordinator_tests.procs import ROOT

pytestmark = pytest.mark.integration


def spinefarm(*args: str, cwd: Path = ROOT, timeout: float = 240, env: dict | None = None
              ) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "spinefarm", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout, env=env)


def spec_copy(tmp_path: Path, name: str, stiffness: float | None = None) -> Path:
    """The built-in 3-segment Tetraspine under another name (and optionally stiffer strings)."""
    text = f"base: tetraspine-ntrt\nname: {name}\n"
    if stiffness is not None:
        text += (f"string_materials:\n  outer: {{stiffness_n_per_m: {stiffness}}}\n"
                 f"  inner: {{stiffness_n_per_m: {stiffness}}}\n")
    path = tmp_path / f"{name}.yaml"
    path.write_text(text)
    return path


def test_a_spec_file_robot_given_by_absolute_path_is_searched_by_two_workers(tmp_path):
    path = spec_copy(tmp_path, "my-spine").resolve()
    out = tmp_path / "run.h5"
    r = spinefarm("search", str(path), "--trials", "4", "--workers", "2", "--duration", "0.3", "--out", str(out),
                  "--api-port", "-1", "--no-verify", "--engine", "bullet")
    assert r.returncode == 0, r.stderr[-2000:]
    with Hdf5Storage.open_read(out) as st:
        meta = st.run_meta()
        assert meta.run_id.startswith("my-spine-") and meta.morphology == "my-spine"
        assert st.counts()["complete"] == 4
        assert meta.morphology_spec["name"] == "my-spine"
        workers = {st.trial(i).worker_id for i in range(4)}
    assert len(workers) >= 1


def test_a_file_named_like_a_builtin_is_simulated_as_the_file(tmp_path):
    stiff = spec_copy(tmp_path, "tetraspine-ntrt", stiffness=3000.0)
    runs = {}
    for label, robot in (("file", str(stiff)), ("builtin", "tetraspine-ntrt")):
        out = tmp_path / f"{label}.h5"
        r = spinefarm("search", robot, "--trials", "1", "--workers", "1", "--duration", "0.5", "--seed", "3",
                      "--out", str(out), "--api-port", "-1", "--no-verify", "--engine", "bullet")
        assert r.returncode == 0, r.stderr[-2000:]
        with Hdf5Storage.open_read(out) as st:
            runs[label] = (st.trial(0), st.run_meta())
    (file_trial, file_meta), (builtin_trial, builtin_meta) = runs["file"], runs["builtin"]
    assert file_meta.run["spec_hash"] != builtin_meta.run["spec_hash"]
    np.testing.assert_array_equal(file_trial.params_unit, builtin_trial.params_unit)  # same run seed
    assert file_trial.distance_m != builtin_trial.distance_m
    params = tmp_path / "params.json"
    params.write_text(json.dumps(dict(zip(file_meta.param_names, file_trial.params, strict=True))))
    replay = spinefarm("trial", str(stiff), "--params", str(params), "--duration", "0.5",
                       "--seed", str(file_trial.seed), "--json")
    assert replay.returncode == 0, replay.stderr
    assert json.loads(replay.stdout)["distance_m"] == pytest.approx(file_trial.distance_m, rel=1e-9)


def test_a_worker_that_cannot_reproduce_the_spec_hash_stops_the_run(tmp_path):
    from spinefarm.coordinator.problem import build_run_config
    from spinefarm.coordinator.service import CoordinatorService
    from spinefarm.coordinator.setup import SearchSettings, new_run
    from spinefarm.protocol.settings import JudgePolicy
    from tests.coordinator_tests.helpers import free_endpoint

    config = build_run_config("forged-spec", "tetraspine-ntrt", duration_s=0.2)
    config = dataclasses.replace(config, spec_hash="0123456789abcdef")
    core, storage = new_run(config, SearchSettings(trials=3, judge=JudgePolicy(enabled=False)),
                            tmp_path / "run.h5")
    endpoint = free_endpoint()
    service = CoordinatorService(core, storage, listen=[endpoint]).start()
    try:
        worker = subprocess.Popen([sys.executable, "-m", "spinefarm", "worker", "--connect", endpoint, "--run",
                                   "forged-spec", "--exit-when-done"], cwd=ROOT, stderr=subprocess.PIPE, text=True)
        assert worker.wait(60) == 3
        assert "spec_hash" in worker.stderr.read()
        wait_for(lambda: core.failure, timeout_s=10, what="the coordinator to hear the worker's problem")
        assert "cannot reproduce the run's spec_hash" in core.failure and "0123456789abcdef" in core.failure
        assert service.wait_done(timeout_s=1.0)  # a failed run is over
        assert core.status()["state"] == "failed"
    finally:
        service.close()


def test_a_local_worker_that_cannot_start_stops_the_search_with_its_error(tmp_path):
    hook = tmp_path / "hook"
    hook.mkdir()
    # a real start-up failure of the worker processes only: the search itself starts normally
    (hook / "sitecustomize.py").write_text(textwrap.dedent("""\
        import sys
        if sys.argv[-1:] == ["--exit-when-done"] or "worker" in sys.argv[1:3]:
            raise SystemExit("worker start-up failed: no licence for the flux capacitor")
    """))
    env = {**os.environ, "PYTHONPATH": str(hook)}
    started = time.monotonic()
    r = spinefarm("search", "sphere:3", "--trials", "5", "--workers", "2", "--out", str(tmp_path / "run.h5"),
                  "--api-port", "-1", env=env, timeout=60)
    assert r.returncode == 1, r.stderr
    assert "flux capacitor" in r.stderr and "local workers cannot start" in r.stderr
    assert time.monotonic() - started < 45


def _children_of(pid: int) -> list[int]:
    out = subprocess.run(["ps", "-o", "pid=", "--ppid", str(pid)], capture_output=True, text=True).stdout
    return [int(x) for x in out.split()]


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    stat = Path(f"/proc/{pid}/stat")
    return stat.exists() and stat.read_text().split()[2] != "Z"


def test_sigkill_of_a_search_leaves_no_worker_behind(tmp_path):
    search = subprocess.Popen([sys.executable, "-m", "spinefarm", "search", "sphere:3", "--trials", "100000",
                               "--workers", "2", "--out", str(tmp_path / "run.h5"), "--api-port", "-1", "--quiet"],
                              cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        workers = wait_for(lambda: (c := _children_of(search.pid)) and len(c) >= 2 and c, timeout_s=30,
                           what="two local workers")
        search.send_signal(signal.SIGKILL)
        search.wait(10)
        wait_for(lambda: not any(_alive(p) for p in workers), timeout_s=15, what="the workers to end")
    finally:
        if search.poll() is None:
            search.kill()


def test_a_search_started_beside_its_own_cli_and_worker_packages_completes(tmp_path):
    for pkg in ("cli", "worker", "api"):
        (tmp_path / pkg).mkdir()
        (tmp_path / pkg / "__init__.py").write_text("raise ImportError('the user\\'s own package')\n")
    r = subprocess.run([sys.executable, "-P", "-m", "spinefarm", "search", "sphere:2", "--trials", "4", "--workers",
                        "2", "--out", str(tmp_path / "run.h5"), "--api-port", "-1"], cwd=tmp_path, capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "4/4 parameter sets" in r.stderr


@pytest.mark.parametrize("name", ["tetraspine", "tetrahedral-complex", "octahedral-complex", "ribbed",
                                  "tetraspine-hardware"])
def test_defining_a_run_loads_no_simulator(name, tmp_path):
    code = textwrap.dedent(f"""\
        import sys
        from spinefarm.coordinator.problem import build_run_config
        from spinefarm.coordinator.setup import SearchSettings, new_run
        config = build_run_config("r", {name!r}, duration_s=1.0)
        core, storage = new_run(config, SearchSettings(trials=2), None)
        core.handle_config(core.config_hash)
        print(sorted(m for m in ("pybullet", "numba", "mujoco") if m in sys.modules))
    """)
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_a_resumed_run_is_rebuilt_from_its_stored_spec(tmp_path):
    from spinefarm.coordinator.problem import build_run_config
    from spinefarm.coordinator.setup import SearchSettings, new_run, resume_run

    path = spec_copy(tmp_path, "gone-soon")
    config = build_run_config("gone-soon-1", str(path), duration_s=0.2)
    _, storage = new_run(config, SearchSettings(trials=2), tmp_path / "run.h5")
    storage.close()
    path.unlink()  # the file the run came from is gone: the run still resumes from what it stored
    core, storage = resume_run(tmp_path / "run.h5")
    try:
        assert core.run_config.spec_hash == config.spec_hash
        assert core.run_config.morphology_spec["name"] == "gone-soon"
    finally:
        storage.close()


def test_run_ids_come_from_the_robot_name_and_are_valid_everywhere(tmp_path):
    from spinefarm.cli.service_commands import default_run_id, robot_name
    from spinefarm.protocol.keys import check_run_id

    path = spec_copy(tmp_path, "stiff")
    assert robot_name(str(path.resolve())) == "stiff"
    for name in ("stiff", "-home-me-stiff.yaml", "..", "sphere-3"):
        rid = default_run_id(name)
        assert check_run_id(rid) == rid and rid[0].isalnum()
    with pytest.raises(ConfigError, match="starting with a letter or digit"):
        check_run_id("-home-me")


def test_an_engine_option_the_engine_lacks_stops_the_search_before_the_run_file(tmp_path):
    r = spinefarm("search", "tetraspine-ntrt", "--engine", "mujoco", "--engine-option", "bogus=1", "--trials", "2",
                  "--workers", "1", "--duration", "0.2", "--out", str(tmp_path / "run.h5"), "--api-port", "-1",
                  timeout=120)
    assert r.returncode == 2, r.stderr[-2000:]
    assert "unknown mujoco engine option 'bogus'" in r.stderr and "segment_contacts" in r.stderr
    assert not (tmp_path / "run.h5").exists()
