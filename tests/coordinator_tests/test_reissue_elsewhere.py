"""A trial that hangs or crashes its simulator is issued again to a worker that has not failed it yet: with
3 live workers its 3 attempts are on 3 distinct workers; with 1 worker it comes back to that worker and is
still given up after 3. Real workers over real Zenoh on loopback, the test objective's poison bands.
Marked slow (10-30 s each with process start-up and trial-process restarts); the default run has the same
rule in-process (test_scheduler.py, test_hostile_peers.py)."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest

from spinefarm.coordinator.problem import build_run_config
from spinefarm.coordinator.setup import SearchSettings, new_run
from spinefarm.storage.hdf5 import read_run
from tests.coordinator_tests.helpers import free_endpoint
from tests.coordinator_tests.procs import coordinator, spinefarm, stop, wait_status

BANDS = {"hang": [0.0, 0.15], "crash": [0.15, 0.3]}
# narrow bands for a longer run: its poisoned trials come late, after every worker is seen alive (the status
# file that shows it is written about every second, and short trials run faster than that)
NARROW_BANDS = {"hang": [0.0, 0.025], "crash": [0.025, 0.05]}
ON_WORKERS = re.compile(r"\(3 attempts\) on (\d+) workers?: (.*)$")


def poisoned_run(out: Path, run_id: str, trials: int, seed: int, bands: dict = BANDS) -> None:
    """The seed fixes each trial's parameters, so which trials are poisoned (by trial number)."""
    cfg = build_run_config(run_id, "sphere:2", seed=seed, duration_s=0.05)
    cfg = dataclasses.replace(cfg, trial_config={"duration_s": 0.05, "poison": bands})
    _, storage = new_run(cfg, SearchSettings(trials=trials, sampler="random", lease_s=30.0), out)
    storage.close()


def run_workers(out: Path, run_id: str, names: list[str], min_limit_s: float, monkeypatch) -> int:
    """Serve the run with these workers until it is done, each logging the verdicts it receives to
    acks-NAME.log beside the run file; the number of trials sampled by the time the coordinator's status
    listed every worker alive (later trials were issued only while all were)."""
    ep = free_endpoint()
    coord = coordinator(ep, out, "--resume", str(out))
    workers = []
    for w in names:
        monkeypatch.setenv("SPINEFARM_ACK_LOG", str(out.parent / f"acks-{w}.log"))
        workers.append(spinefarm("worker", "--connect", ep, "--run", run_id, "--worker-id", w, "--batch", "1",
                                 "--exit-when-done", "--min-trial-limit", str(min_limit_s)))
    monkeypatch.delenv("SPINEFARM_ACK_LOG")
    try:
        st = wait_status(out, lambda st: {w["worker_id"] for w in st["workers"] if w["alive"]} >= set(names),
                         "every worker alive", timeout_s=60.0)
        assert coord.wait(150) == 0
        assert all(w.wait(30) == 0 for w in workers)
    finally:
        stop(coord, *workers)
    return int(st["trials_sampled"])


def requeued_on(out: Path, names: list[str]) -> dict[int, list[str]]:
    """trial id -> the workers that were told "requeued" for it (it timed out or crashed there), once each time."""
    seen: dict[int, list[str]] = {}
    for w in names:
        for line in (out.parent / f"acks-{w}.log").read_text().splitlines():
            _, tid, verdict, *_ = line.split()
            if verdict == "requeued":
                seen.setdefault(int(tid), []).append(w)
    return seen


def poison_rows(out: Path, bands: dict = BANDS) -> list[tuple[int, str, str]]:
    """(trial id, status, reason) of every trial in a poison band."""
    _, cols = read_run(out)
    return [(i, cols["status"][i].decode(), cols["reason"][i].decode()) for i in range(len(cols["status"]))
            if cols["params_unit"][i, 0] < bands["crash"][1]]


@pytest.mark.slow
def test_a_hanging_or_crashing_trial_is_tried_by_three_distinct_workers(tmp_path, monkeypatch):
    out = tmp_path / "run.h5"
    poisoned_run(out, "elsewhere", 80, seed=102, bands=NARROW_BANDS)  # poisoned: 60 (crash), 63 (hang)
    names = ["w0", "w1", "w2"]
    sampled_before_all_alive = run_workers(out, "elsewhere", names, 0.3, monkeypatch)
    rows = poison_rows(out, NARROW_BANDS)
    requeued = requeued_on(out, names)
    checked = 0
    for tid, status, reason in rows:
        assert status == "failed" and reason.startswith(("timeout:", "crashed:")), (tid, reason)
        m = ON_WORKERS.search(reason)
        assert m is not None, reason
        if tid >= sampled_before_all_alive:
            assert m.group(1) == "3" and sorted(m.group(2).split(", ")) == names, (tid, reason)
            assert sorted(requeued[tid]) == names, (tid, requeued[tid])  # once on each worker
            checked += 1
    assert [tid for tid, _, _ in rows] == [60, 63] and checked >= 1, (sampled_before_all_alive, rows)


@pytest.mark.slow
def test_with_one_worker_a_hanging_or_crashing_trial_is_still_given_up_after_three(tmp_path, monkeypatch):
    out = tmp_path / "run.h5"
    poisoned_run(out, "alone", 4, seed=1)  # poisoned: 3 (hang)
    run_workers(out, "alone", ["w0"], 0.3, monkeypatch)
    rows = poison_rows(out)
    assert requeued_on(out, ["w0"]) == {3: ["w0"] * 3}
    assert [(tid, reason[:8]) for tid, _, reason in rows] == [(3, "timeout:")]
    for tid, status, reason in rows:
        assert status == "failed" and reason.startswith(("timeout:", "crashed:")), (tid, reason)
        assert reason.endswith("(3 attempts) on 1 worker: w0"), (tid, reason)
