"""A per-trial wall-clock limit: a hung or crashing simulator costs one trial, the worker goes on, and a
trial that times out on 3 attempts is stored as failed(timeout) and not issued again."""

from __future__ import annotations

import dataclasses
import math
import multiprocessing as mp
import os
import signal
import threading
import time

import pytest

from spinefarm.coordinator.problem import build_run_config
from spinefarm.coordinator.setup import SearchSettings, new_run
from spinefarm.protocol.work import TrialAssignment
from spinefarm.storage.hdf5_reader import read_run
from spinefarm.worker.service.sandbox import (
    SandboxProblem,
    SandboxStopped,
    TrialLimit,
    TrialSandbox,
    _child,
    simulated_s,
    task_kind,
)
from tests.coordinator_tests.helpers import free_endpoint
from tests.coordinator_tests.procs import coordinator, spinefarm, stop

BANDS = {"hang": [0.0, 0.15], "crash": [0.15, 0.25]}


def poisoned(run_id: str, delay_s: float):
    cfg = build_run_config(run_id, "sphere:2", duration_s=delay_s)
    return dataclasses.replace(cfg, trial_config={"duration_s": delay_s, "poison": BANDS})


def at(u0: float, n: int = 2) -> TrialAssignment:
    return TrialAssignment(0, 1, (u0,) + (0.5,) * (n - 1), 7, 60.0, None)


def test_hung_and_crashing_trials_end_in_bounded_time_and_the_sandbox_goes_on():
    box = TrialSandbox(poisoned("limit", 0.05), TrialLimit(min_s=0.5, first_factor=2.0))
    try:
        first = box.run(at(0.9))
        assert first.ok and first.extras["time_limit_s"] == 1.0  # first_factor x min before a measurement
        t0 = time.monotonic()
        hung = box.run(at(0.05))
        assert hung.reason.startswith("timeout:") and time.monotonic() - t0 < 2.0
        # max(min_s, 8 x the rate the first trial measured x 0.05 s): its wall time over its 0.05 s simulated
        assert math.isclose(hung.extras["time_limit_s"], max(0.5, 8 * first.wall_time_s / 0.05 * 0.05))
        assert box.run(at(0.9)).ok  # a fresh trial process
        crashed = box.run(at(0.2))
        assert crashed.reason.startswith("crashed:") and "SIGSEGV" in crashed.reason
        assert box.run(at(0.9)).ok and box.restarts == 2
        threading.Timer(0.2, box.stop.set).start()  # the worker is stopping: a hung trial is abandoned
        t0 = time.monotonic()
        assert box.run(at(0.05)) is None and time.monotonic() - t0 < 1.5
    finally:
        box.close()


def test_a_trial_process_stopped_with_its_worker_is_no_crash():
    """A batch system ending the job (scancel), or a terminal's hang-up, signals the worker's whole process
    group: the trial process dies of the same SIGTERM the worker stops on. That trial is abandoned (re-issued
    once its lease expires), not reported as a crash that counts towards its three strikes; a trial process
    killed while its worker goes on is still a crash."""
    box = TrialSandbox(poisoned("job", 3.0), TrialLimit(min_s=30.0))
    try:
        for stops, expected in ((True, None), (False, "crashed:")):
            box.stop.clear()
            box.start()  # ready: the signal lands inside the trial (3 s), not in the start-up

            def stop_the_job(stops: bool = stops) -> None:
                os.kill(box._proc.pid, signal.SIGTERM)  # the group's signal reaches the child ...
                if stops:
                    time.sleep(0.05)  # ... and the worker's own handler sets its stop event a moment later
                    box.stop.set()
            threading.Timer(1.0, stop_the_job).start()
            result = box.run(at(0.9))
            if expected is None:
                assert result is None
            else:
                assert result.reason.startswith(expected) and "SIGTERM" in result.reason, result.reason
    finally:
        box.close()


def test_a_worker_stopped_while_its_trial_process_starts_reports_no_problem():
    """Stopping a worker (or its whole job) while its trial process starts (imports, compiled kernels: up to a
    minute on a fresh install) is no problem of the run's: reported as one, it would stop the whole search."""
    box = TrialSandbox(poisoned("starting", 0.05), TrialLimit(min_s=30.0))
    try:
        box.stop.set()  # the worker's stop came first
        with pytest.raises(SandboxStopped):
            box.start()
        box.stop.clear()

        def stop_the_job() -> None:  # the job's SIGTERM reaches the starting child, then the worker
            while box._proc is None or box._proc.pid is None:
                time.sleep(0.001)
            os.kill(box._proc.pid, signal.SIGTERM)
            time.sleep(0.05)
            box.stop.set()
        threading.Thread(target=stop_the_job).start()
        with pytest.raises(SandboxStopped):
            box.start()
        assert box._proc is None
    finally:
        box.close()


def kill_starting_children(box: TrialSandbox, times: int) -> threading.Thread:
    """SIGKILL the box's trial process `times` times, each as soon as it exists (before it is ready)."""
    def run() -> None:
        seen: set[int] = set()
        while len(seen) < times:
            proc = box._proc
            if proc is not None and proc.pid is not None and proc.pid not in seen:
                seen.add(proc.pid)
                os.kill(proc.pid, signal.SIGKILL)
            time.sleep(0.001)
    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t


def test_a_trial_process_killed_while_it_starts_is_started_again():
    """The OOM killer or a stray kill while the trial process starts is no problem of the run's (reported, it
    stops a search no other worker has served); the same death at every start is."""
    box = TrialSandbox(poisoned("oom", 0.05), TrialLimit(min_s=30.0))
    try:
        killer = kill_starting_children(box, 1)
        box.start()
        killer.join(5)
        assert box.run(at(0.9)).ok
    finally:
        box.close()
    box = TrialSandbox(poisoned("oom", 0.05), TrialLimit(min_s=30.0))
    try:
        kill_starting_children(box, 3)
        with pytest.raises(SandboxProblem, match=r"did not start \(signal SIGKILL, 3 times\)"):
            box.start()
    finally:
        box.close()


def test_a_trial_process_whose_worker_is_gone_before_it_is_ready_exits_quietly(capfd):
    # A worker killed while its trial process starts: the process finds no one to say "ready" to.
    ctx = mp.get_context("spawn")
    parent, child = ctx.Pipe()
    proc = ctx.Process(target=_child, args=(child, poisoned("gone", 0.05)), daemon=True)
    proc.start()
    child.close()
    parent.close()
    proc.join(60)
    assert proc.exitcode == 0
    assert "Traceback" not in capfd.readouterr().err


def test_a_frozen_physics_trial_times_out_from_its_measured_cost_and_the_next_one_runs():
    cfg = build_run_config("physics", "tetraspine", duration_s=0.2)
    box = TrialSandbox(cfg, TrialLimit(min_s=1.0, first_factor=300.0))
    n = len(cfg.space())
    try:
        warm = box.run(at(0.3, n))
        assert warm.ok, warm.reason
        limit = box.limit.limit_s(simulated_s(cfg, at(0.4, n)), *task_kind(cfg, at(0.4, n)))
        assert 1.0 <= limit <= max(1.0, 8 * 1.25 * warm.wall_time_s / 0.2 * 0.2)
        pid = box._proc.pid
        threading.Timer(0.05, os.kill, (pid, signal.SIGSTOP)).start()  # stands in for a call that never returns
        t0 = time.monotonic()
        frozen = box.run(at(0.4, n))
        assert frozen.reason.startswith("timeout:") and frozen.extras["time_limit_s"] == limit
        assert time.monotonic() - t0 < limit + 5.0
        assert box.run(at(0.5, n)).ok
    finally:
        box.close()


def test_a_hanging_trial_is_given_up_after_three_timeouts_and_the_run_reaches_its_budget(tmp_path):
    out, ep = tmp_path / "run.h5", free_endpoint()
    _, storage = new_run(poisoned("poison", 0.1), SearchSettings(trials=30, sampler="random", lease_s=30.0), out)
    storage.close()
    coord = coordinator(ep, out, "--resume", str(out))
    workers = [spinefarm("worker", "--connect", ep, "--run", "poison", "--worker-id", f"w{i}", "--batch", "1",
                         "--exit-when-done", "--min-trial-limit", "0.3") for i in range(3)]
    try:
        assert coord.wait(150) == 0
        assert all(w.wait(30) == 0 for w in workers)
    finally:
        stop(coord, *workers)
    _, cols = read_run(out)
    status = [s.decode() for s in cols["status"]]
    reasons = [r.decode() for r in cols["reason"]]
    u0 = cols["params_unit"][:, 0]
    assert len(status) == 30 and "waiting" not in status
    for i in range(30):
        if u0[i] < 0.15:
            assert status[i] == "failed" and reasons[i].startswith("timeout:") and "(3 attempts)" in reasons[i]
        elif u0[i] < 0.25:
            assert status[i] == "failed" and reasons[i].startswith("crashed:"), reasons[i]
        else:
            assert status[i] == "complete", reasons[i]
    assert any(u < 0.15 for u in u0) and (cols["time_limit_s"][[s == "complete" for s in status]] > 0).all()


def test_each_kind_of_task_has_its_own_measured_cost():
    """A screen's rate does not set a judge's limit: a kind not yet measured gets first_factor x the slowest
    measured rate scaled to its finer step (hand computed)."""
    limit = TrialLimit(min_s=1.0, factor=8.0, first_factor=10.0)
    screen, judge = ("trial", "mujoco", False, 0.002, 3.0), ("judge", "bullet", False, 0.00025, None)
    assert limit.limit_s(4.0, screen, 0.002) == 10.0  # nothing measured: first_factor x min_s
    limit.observe(0.8, 4.0, screen, 0.002)  # 0.2 wall s per simulated s
    assert limit.limit_s(4.0, screen, 0.002) == 8.0 * 0.2 * 4.0
    assert limit.limit_s(31.0, judge, 0.00025) == 10.0 * 0.2 * 8.0 * 31.0  # the step 8x finer
    limit.observe(62.0, 31.0, judge, 0.00025)
    assert limit.limit_s(31.0, judge, 0.00025) == 8.0 * 2.0 * 31.0
    assert limit.limit_s(4.0, screen, 0.002) == 8.0 * 0.2 * 4.0  # the screen's own rate is untouched


def test_a_judge_at_a_finer_step_in_another_engine_is_not_timed_out_by_the_screens_pace():
    """A MuJoCo 2 ms screen runs ~30x faster per simulated second than a Bullet 0.25 ms judge; with one
    measured rate every judge of a screened search timed out (and no best was ever verified)."""
    from spinefarm.protocol.settings import TaskFidelity

    cfg = build_run_config("judge-pace", "tetraspine", duration_s=4.0,
                           trial_overrides={"engine": "mujoco", "dt_s": 0.002, "settle_s": 0.0})
    box = TrialSandbox(cfg, TrialLimit(min_s=0.2, first_factor=100.0))
    n = len(cfg.space())
    screen = TaskFidelity("trial", "mujoco", 0.002, 0.0)
    try:
        for u in (0.3, 0.35, 0.4):
            r = box.run(dataclasses.replace(at(u, n), fidelity=screen))
            assert r.ok, r.reason
        judge = box.run(dataclasses.replace(at(0.4, n), fidelity=TaskFidelity("judge", "bullet", 0.00025, 0.0)))
        assert judge.ok, judge.reason
        assert judge.extras["time_limit_s"] > judge.wall_time_s
    finally:
        box.close()


_ORPHAN_PARENT = """
import sys, threading, time
from tests.worker_tests.test_trial_limit import at, poisoned
from spinefarm.worker.service.sandbox import TrialSandbox
box = TrialSandbox(poisoned("orphan", 0.05))
box.start()
threading.Thread(target=box.run, args=(at(0.05),), daemon=True).start()  # a trial that hangs
time.sleep(1.0)
print(box._proc.pid, flush=True)
time.sleep(600)
"""


def _gone(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] == "Z"  # dead, not yet reaped
    except FileNotFoundError:
        return True


def test_a_trial_process_dies_with_its_worker_even_mid_trial():
    """The child asks the kernel for SIGKILL when its parent dies (PR_SET_PDEATHSIG): a worker SIGKILLed while
    its trial hangs leaves no trial process behind (a hung one would never read its pipe's end)."""
    import subprocess
    import sys

    parent = subprocess.Popen([sys.executable, "-c", _ORPHAN_PARENT], stdout=subprocess.PIPE, text=True,
                              cwd=os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
    try:
        child_pid = int(parent.stdout.readline())
        assert not _gone(child_pid)
        parent.kill()
        parent.wait(10)
        deadline = time.monotonic() + 10.0
        while not _gone(child_pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        alive = not _gone(child_pid)
        if alive:
            os.kill(child_pid, signal.SIGKILL)
        assert not alive, "the trial process outlived its worker"
    finally:
        parent.kill()
