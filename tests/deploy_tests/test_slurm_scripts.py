"""deploy/slurm/*.sbatch: their --help and --dry-run, run by bash as sbatch would run them."""

from __future__ import annotations

import os
import shlex
import subprocess

from tests.coordinator_tests.procs import ROOT

SLURM = ROOT / "deploy" / "slurm"


def script(name: str, *args: str, **env: str) -> subprocess.CompletedProcess[str]:
    clean = {k: v for k, v in os.environ.items() if not k.startswith(("SLURM_", "RUN_", "SEARCH_"))}
    return subprocess.run(["bash", str(SLURM / name), *args], env={**clean, **env}, capture_output=True, text=True,
                          timeout=30)


def test_help_names_every_setting_and_needs_no_environment():
    for name, settings in (("coordinator.sbatch", ("RUN_DIR", "RUN_ID", "MORPHOLOGY", "TRIALS", "ADVERTISE_HOST")),
                           ("worker.sbatch", ("RUN_DIR", "RUN_ID", "ENDPOINT_WAIT_S"))):
        out = script(name, "--help")
        assert out.returncode == 0, out.stderr
        assert all(s in out.stdout for s in settings) and "sbatch" in out.stdout and "#" not in out.stdout


def test_the_coordinator_dry_run_starts_a_new_run_then_resumes_it(tmp_path):
    env = {"RUN_DIR": str(tmp_path), "RUN_ID": "tetra-1", "MORPHOLOGY": "sphere:3", "TRIALS": "40",
           "SEARCH_ARGS": "--rungs 1,3 --no-verify", "PORT": "7500", "ADVERTISE_HOST": "node7"}
    out = script("coordinator.sbatch", "--dry-run", **env)
    assert out.returncode == 0, out.stderr
    endpoint, _, command = out.stdout.splitlines()
    assert endpoint == f"endpoint tcp/node7:7500 -> {tmp_path}/tetra-1.endpoint"
    argv = shlex.split(command)
    assert argv[:3] == ["spinefarm", "coordinator", "sphere:3"]
    assert argv[argv.index("--out") + 1] == f"{tmp_path}/tetra-1.h5" and "--rungs" in argv
    assert argv[argv.index("--listen") + 1] == "tcp/0.0.0.0:7500"
    assert argv[argv.index("--credentials") + 1] == f"{tmp_path}/credentials"
    assert list(tmp_path.iterdir()) == [], "a dry run changed the run folder"
    (tmp_path / "tetra-1.h5").write_bytes(b"")
    argv = shlex.split(script("coordinator.sbatch", "--dry-run", **env).stdout.splitlines()[2])
    assert argv[:4] == ["spinefarm", "coordinator", "--resume", f"{tmp_path}/tetra-1.h5"]
    assert "sphere:3" not in argv and argv[argv.index("--trials") + 1] == "40"


def test_the_worker_dry_run_names_its_array_task_and_reads_the_endpoint_file(tmp_path):
    out = script("worker.sbatch", "--dry-run", RUN_DIR=str(tmp_path), RUN_ID="tetra-1", SLURM_ARRAY_JOB_ID="812",
                 SLURM_ARRAY_TASK_ID="5", SPINEFARM="/opt/venv/bin/spinefarm")
    assert out.returncode == 0, out.stderr
    argv = shlex.split(out.stdout.splitlines()[1])
    assert argv[:2] == ["/opt/venv/bin/spinefarm", "worker"]
    assert argv[argv.index("--worker-id") + 1] == "slurm-812-5"
    assert argv[argv.index("--credentials") + 1] == f"{tmp_path}/worker.cred"
    assert "--exit-when-done" in argv and f"{tmp_path}/tetra-1.endpoint" in out.stdout


def test_mistakes_are_one_line_errors(tmp_path):
    missing = script("worker.sbatch", "--dry-run")
    assert missing.returncode != 0 and "RUN_DIR" in missing.stderr
    unknown = script("coordinator.sbatch", "--bogus", RUN_DIR=str(tmp_path))
    assert unknown.returncode == 2 and "unknown option --bogus" in unknown.stderr
    waits = script("worker.sbatch", RUN_DIR=str(tmp_path), ENDPOINT_WAIT_S="0")
    assert waits.returncode == 1 and "no coordinator endpoint" in waits.stderr
