"""The SLURM deployment run for real on this machine: munge, slurmctld and slurmd with a minimal slurm.conf
(this host as controller and as one node, on loopback), deploy/slurm/coordinator.sbatch and a worker
array job; part of the array is cancelled mid-run and the run file must still hold its exact budget."""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
import time
from contextlib import ExitStack, suppress
from pathlib import Path
from typing import Any

from tests.deploy.host import ROOT, RUN_DIR, DeployError, host_prerequisite, log, sh, wait_until
from tests.deploy.run_file import check_run_file

RUN_ID = "deploy-slurm"
TRIALS = 120
ARRAY = 4
SEARCH_ARGS = "--rungs 0.3,0.9 --eta 3 --no-verify"
SLURM_CONF = """ClusterName=spinefarm-test
SlurmctldHost={host}(127.0.0.1)
SlurmctldPort={ctld_port}
SlurmdPort={slurmd_port}
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation={d}/state
SlurmdSpoolDir={d}/spool
SlurmctldPidFile={d}/slurmctld.pid
SlurmdPidFile={d}/slurmd.pid
SlurmctldLogFile={d}/slurmctld.log
SlurmdLogFile={d}/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SlurmdParameters=config_overrides
ReturnToService=2
MpiDefault=none
NodeName={host} NodeAddr=127.0.0.1 CPUs=8 RealMemory=1000 State=UNKNOWN
PartitionName=test Nodes={host} Default=YES MaxTime=INFINITE State=UP
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Slurm:
    """The daemons and the environment every SLURM command of the test uses."""

    def __init__(self, stack: ExitStack) -> None:
        self.dir = RUN_DIR / "slurm"
        for daemon in ("slurmctld", "slurmd"):  # left by an earlier run that was killed
            _stop_stale(self.dir / f"{daemon}.pid", daemon)
        shutil.rmtree(self.dir, ignore_errors=True)
        for sub in ("state", "spool"):
            (self.dir / sub).mkdir(parents=True)
        self.host = socket.gethostname().split(".")[0]
        conf = self.dir / "slurm.conf"
        conf.write_text(SLURM_CONF.format(host=self.host, d=self.dir, ctld_port=free_port(),
                                          slurmd_port=free_port()))
        self.env = dict(os.environ, SLURM_CONF=str(conf))
        self.stack = stack

    def cmd(self, *args: str, check: bool = True, timeout_s: float = 60.0) -> str:
        return sh(*args, env=self.env, check=check, timeout_s=timeout_s).stdout

    def start(self) -> None:
        with host_prerequisite("this host cannot run munge and the SLURM daemons"):
            self._start()

    def _start(self) -> None:
        self._munge()
        for daemon in (["slurmctld", "-D", "-i"], ["slurmd", "-D", "-N", self.host]):
            log_file = open(self.dir / f"{daemon[0]}.out", "wb")  # noqa: SIM115 (lives as long as the daemon)
            proc = subprocess.Popen(daemon, env=self.env, stdout=log_file, stderr=subprocess.STDOUT)
            self.stack.callback(_stop, proc)
            time.sleep(1.0)
            if proc.poll() is not None:
                raise DeployError(f"{daemon[0]} exited {proc.returncode}: {self._tail(daemon[0])}")
        wait_until(lambda: self.cmd("sinfo", "-h", "-o", "%T", check=False).strip() in ("idle", "mixed"), 60,
                   f"the SLURM node to be idle ({self._tail('slurmd')})")

    def _munge(self) -> None:
        if sh("munge", "-n", check=False).returncode == 0:
            return  # a munged is running already: use it, leave it running
        key = Path("/etc/munge/munge.key")
        if not key.exists():
            key.parent.mkdir(exist_ok=True)
            sh("mungekey", "--create", "--keyfile", key)
            shutil.chown(key, "munge", "munge")
            key.chmod(0o400)
        Path("/run/munge").mkdir(exist_ok=True)
        shutil.chown("/run/munge", "munge", "munge")
        sh("runuser", "-u", "munge", "--", "munged")
        self.stack.callback(_stop_munged)
        wait_until(lambda: sh("munge", "-n", check=False).returncode == 0, 30, "munged to answer")

    def _tail(self, name: str) -> str:
        for path in (self.dir / f"{name}.log", self.dir / f"{name}.out"):
            if path.exists() and path.read_text(errors="replace").strip():
                return " | ".join(path.read_text(errors="replace").strip().splitlines()[-3:])
        return "no log"

    def sbatch(self, script: str, env: dict[str, str], *args: str) -> str:
        out = sh("sbatch", "--parsable", *args, str(ROOT / "deploy" / "slurm" / script),
                 env=dict(self.env, **env), timeout_s=60).stdout
        return out.strip().split(";")[0]

    def jobs(self, job: str) -> list[str]:
        return self.cmd("squeue", "-h", "-j", job, "-r", "-o", "%i %T", check=False).strip().splitlines()


def _stop(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10)


def _stop_stale(pidfile: Path, name: str) -> None:
    with suppress(OSError, ValueError):
        pid = int(pidfile.read_text().strip())
        if Path(f"/proc/{pid}/comm").read_text().strip() == name:
            log(f"stopping the {name} a killed earlier run left (pid {pid})")
            os.kill(pid, 15)
            wait_until(lambda: not Path(f"/proc/{pid}").exists(), 30, f"the stale {name} to stop")


def _stop_munged() -> None:
    pidfile = Path("/run/munge/munged.pid")
    if pidfile.exists():
        with suppress(ValueError, ProcessLookupError):
            os.kill(int(pidfile.read_text().strip()), 15)


def run_status(run_dir: Path) -> dict[str, Any]:
    try:
        return json.loads((run_dir / f"{RUN_ID}.h5.status.json").read_text())
    except (OSError, ValueError):
        return {}


def scenario(slurm: Slurm, run_dir: Path) -> dict[str, Any]:
    spinefarm = Path(sys.executable).parent / "spinefarm"
    env = {"RUN_DIR": str(run_dir), "RUN_ID": RUN_ID, "MORPHOLOGY": "sphere:4", "TRIALS": str(TRIALS),
           "SEED": "9", "SEARCH_ARGS": SEARCH_ARGS, "PORT": str(free_port()), "LISTEN_HOST": "127.0.0.1",
           "ADVERTISE_HOST": "127.0.0.1", "SPINEFARM": str(spinefarm)}
    t0 = time.monotonic()
    coord = slurm.sbatch("coordinator.sbatch", env, "--chdir", str(run_dir), "--output",
                         str(run_dir / "coordinator-%j.out"))
    array = slurm.sbatch("worker.sbatch", env, f"--array=0-{ARRAY - 1}", "--chdir", str(run_dir), "--output",
                         str(run_dir / "worker-%A_%a.out"))
    log(f"submitted coordinator job {coord} and worker array {array} (0-{ARRAY - 1})")
    wait_until(lambda: run_status(run_dir).get("trials_complete", 0) >= 30, 180,
               f"30 complete trials from the SLURM jobs ({_outputs(run_dir)})")
    cancelled = [f"{array}_1", f"{array}_2"]
    cancelled_at = run_status(run_dir).get("trials_complete", 0)
    log(f"scancel {' '.join(cancelled)} mid-run")
    slurm.cmd("scancel", *cancelled)
    wait_until(lambda: not slurm.jobs(coord), 300, f"the coordinator job to end ({_outputs(run_dir)})")
    wait_until(lambda: not slurm.jobs(array), 90, "the rest of the worker array to exit after the run")
    elapsed = time.monotonic() - t0
    final = run_status(run_dir)
    if final.get("state") != "done":
        raise DeployError(f"the SLURM run ended in state {final.get('state')!r}: {_outputs(run_dir)}")
    figures = {"search_s": round(elapsed, 1), "array_tasks": ARRAY, "cancelled_tasks": cancelled,
               "cancelled_at": cancelled_at}
    figures.update(check_run_file(run_dir / f"{RUN_ID}.h5", TRIALS))
    return figures


def _outputs(run_dir: Path) -> str:
    lines = []
    for path in sorted(run_dir.glob("*.out")):
        text = path.read_text(errors="replace").strip().splitlines()
        lines.append(f"{path.name}: {text[-1][-200:] if text else '(empty)'}")
    return "; ".join(lines) or "no job output yet"


def run(stack: ExitStack) -> dict[str, Any]:
    t0 = time.monotonic()
    with ExitStack() as daemons:
        slurm = Slurm(daemons)
        slurm.start()
        started_s = time.monotonic() - t0
        run_dir = RUN_DIR / "slurm-run"
        shutil.rmtree(run_dir, ignore_errors=True)
        run_dir.mkdir(parents=True)
        try:
            figures = scenario(slurm, run_dir)
        finally:
            slurm.cmd("scancel", "--partition=test", check=False)
        figures["slurm_version"] = slurm.cmd("sinfo", "--version", check=False).strip()
    figures["daemons_start_s"] = round(started_s, 1)
    return figures
