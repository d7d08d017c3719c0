"""Soak: a multi-fidelity search on 4 workers under a random schedule of faults runs to its exact budget.

--minutes sizes the budget (--rate parameter sets a second: 3.5 on 2 shared cores under heavy load); faults
go on until the run is over: worker SIGKILLs and SIGSTOPs (3-8 s), coordinator SIGKILLs, each
process restarted automatically whenever it exits before the run is over (as compose's restart policies
do; nothing is restarted by hand), hang- and crash-poison trials (the
test objective's fault bands: a trial there sleeps for ever or segfaults its trial process), a forging
peer (results for leases it was never given, also under other workers' ids), a 10 s network
partition of two workers (network namespaces, tests/netns.py; without root the workers share loopback
and the partition is skipped, said in the JSON) and a worker frozen a few seconds before the run ends
until it is done.

Checked from the run file and the workers' acknowledgement logs (SPINEFARM_ACK_LOG): every parameter set
of the budget evaluated, no row left waiting, 0 lost (acknowledged as stored, absent or different in
the file), 0 duplicated (acknowledged as stored twice), 0 forged rows stored as complete, every audit
(a quarter of the results, every new best) and every judge of a new best run and none left pending across
the coordinator kills
(`tasks_pending_at_end`), no process
left running once the run is over, no exit the schedule did not cause, and how the workers left: each
frozen one is woken when the run is done and the coordinator waits for it, so none should have to wait
out its --coordinator-timeout (`workers_timed_out`; `workers_exit_s`: from the coordinator's exit to the
last worker's).
usage: python bench/soak.py [--minutes 30] [--rate 3.5] [--seed 1] [--dir DIR]      (one JSON object)
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import re
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from spinefarm.coordinator.problem import build_run_config  # noqa: E402
from spinefarm.coordinator.setup import SearchSettings, new_run  # noqa: E402
from spinefarm.protocol.settings import JUDGE_DT_S, AuditPolicy, JudgePolicy, Rung  # noqa: E402
from spinefarm.storage.hdf5_reader import read_evaluations, read_run  # noqa: E402

POISON = {"hang": [0.0, 0.015], "crash": [0.015, 0.03]}   # on the first unit parameter
FORGED_M = 1234.5
RUNGS_S = (0.1, 0.3)        # test-objective trials take their duration in wall time
PARTITION_S = 10.0
# a share of the results (and every new best) is audited by another worker, and every new best judged (the judge
# named, so the test objective has one), so coordinator kills find audits and judges pending: each must be issued
# again and none left pending when the run ends
AUDIT_FRACTION = 0.25
N_WORKERS = 4
COORDINATOR_TIMEOUT_S = 60   # a restarted coordinator validates and rewrites its file: slow under load


def make_run(path: Path, run_id: str, trials: int, seed: int) -> None:
    cfg = build_run_config(run_id, "sphere:4", seed=seed, duration_s=RUNGS_S[-1])
    cfg = replace(cfg, trial_config={"duration_s": RUNGS_S[-1], "poison": POISON})
    _, storage = new_run(cfg, SearchSettings(trials=trials, sampler="random", lease_s=20.0, rungs=RUNGS_S,
                                             audit=AuditPolicy(fraction=AUDIT_FRACTION),
                                             judge=JudgePolicy(rung=Rung("bullet", JUDGE_DT_S))), path)
    storage.close()


class Net:
    """Where each process runs: the hub and two worker hosts in namespaces, or plain loopback."""

    def __init__(self, want_netns: bool) -> None:
        from tests.coordinator_tests.helpers import free_endpoint
        from tests.netns import ThreeHosts, netns_unavailable

        self.why_not = netns_unavailable() if want_netns else "not asked for"
        self.hosts = ThreeHosts(delay_ms=1.0, loss_pct=0.0).open() if self.why_not is None else None
        self.loop_ep = free_endpoint()

    def coordinator_args(self) -> tuple[list[str], str]:
        if self.hosts is None:
            return [], self.loop_ep
        return self.hosts.exec_args(self.hosts.hub), self.hosts.coordinator_listen

    def worker_args(self, i: int) -> tuple[list[str], str]:
        if self.hosts is None:
            return [], self.loop_ep
        side = "a" if i < N_WORKERS // 2 else "b"
        return self.hosts.exec_args(self.hosts.host(side)), self.hosts.endpoint(side)

    def cut(self, on: bool) -> None:
        if self.hosts is not None:
            self.hosts.cut("b", on)

    def close(self) -> None:
        if self.hosts is not None:
            self.hosts.close()


class Proc:
    """A process restarted whenever it dies before the run is over (a restart policy, not a person)."""

    def __init__(self, name: str, argv: list[str], env: dict[str, str], log: Path) -> None:
        self.name, self.argv, self.env, self.log = name, argv, env, log
        self.proc: subprocess.Popen | None = None
        self.starts = 0
        self.stopped_until: float | None = None
        self.run_id = ""
        self.killed = False   # by the schedule: its next exit is expected
        self.exited_at = 0.0  # when it exited 0 (it was told the run is over)
        self.start()

    def start(self) -> None:
        with open(self.log, "ab") as err:
            self.proc = subprocess.Popen(self.argv, env=self.env, cwd=ROOT, stdin=subprocess.DEVNULL,
                                         stdout=subprocess.DEVNULL, stderr=err)
        self.starts += 1

    def signal(self, sig: int) -> None:
        if self.proc is not None and self.proc.poll() is None:
            os.kill(self.proc.pid, sig)
            self.killed = self.killed or sig == signal.SIGKILL

    def restart(self) -> bool:
        """Start it again; True if its exit was not one the schedule caused."""
        unexpected, self.killed = not self.killed, False
        self.start()
        return unexpected

    def resume_if_due(self, now: float, force: bool = False) -> None:
        if self.stopped_until is not None and (force or now >= self.stopped_until):
            self.signal(signal.SIGCONT)
            self.stopped_until = None


def start_processes(net: Net, path: Path, run_id: str, tmp: Path) -> tuple[Proc, list[Proc]]:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    prefix, listen = net.coordinator_args()
    coord = Proc("coordinator", [*prefix, sys.executable, "-m", "spinefarm", "coordinator", "--resume", str(path),
                                 "--listen", listen, "--api-port", "-1", "--quiet"], env, tmp / "coordinator.log")
    coord.run_id = run_id
    workers = []
    for i in range(N_WORKERS):
        prefix, ep = net.worker_args(i)
        wenv = dict(env, SPINEFARM_ACK_LOG=str(tmp / f"acks-w{i}.log"))
        workers.append(Proc(f"w{i}", [*prefix, sys.executable, "-m", "spinefarm", "worker", "--connect", ep,
                                      "--run", run_id, "--worker-id", f"w{i}", "--exit-when-done",
                                      "--coordinator-timeout", str(COORDINATOR_TIMEOUT_S), "--min-trial-limit",
                                      "0.5"],
                            wenv, tmp / f"w{i}.log"))
    return coord, workers


def forge(endpoint: str, run_id: str, n: int) -> None:
    """A peer that submits results for leases it was never given, under its own and others' worker ids."""
    import zenoh

    from spinefarm.coordinator.service import zenoh_config
    from spinefarm.protocol import keys
    from spinefarm.protocol.envelope import encode_message
    from spinefarm.protocol.results import TrialResult
    from spinefarm.protocol.states import TrialStatus
    from spinefarm.protocol.submissions import ResultSubmission, SubmittedResult

    rng = random.Random(7)
    session = zenoh.open(zenoh_config("client", connect=[endpoint]))
    try:
        for k in range(n):
            tid = rng.randrange(0, 200)
            result = TrialResult(TrialStatus.COMPLETE, "", FORGED_M, 1e5, 1e3, 1.0, 0.01, 0.3, 0.3, 1.0,
                                 rng.randrange(2**31), trial_id=tid, worker_id="forger")
            who = rng.choice(["forger", "w0", "w3"])
            sub = ResultSubmission(who, (SubmittedResult(rng.randrange(2**62), result),))
            for _ in session.get(keys.results(run_id), payload=encode_message(sub), timeout=2.0):
                pass
            time.sleep(0.02 if k % 10 else 0.2)
    finally:
        session.close()


def inject(kind: str, rng: random.Random, coord: Proc, workers: list[Proc], net: Net, now: float,
           counts: Counter, forger: list) -> float | None:
    """Do one fault; returns when a partition heals, if this was one."""
    if kind == "worker_kill":
        rng.choice(workers).signal(signal.SIGKILL)
    elif kind == "worker_stop":
        w = rng.choice([w for w in workers if w.stopped_until is None] or workers)
        w.signal(signal.SIGSTOP)
        w.stopped_until = now + rng.uniform(3.0, 8.0)
    elif kind == "coordinator_kill":
        coord.signal(signal.SIGKILL)
    elif kind == "end_stop":
        w = rng.choice([w for w in workers if w.stopped_until is None] or workers)
        w.signal(signal.SIGSTOP)
        w.stopped_until = math.inf  # woken when the run is done
    elif kind == "forge":
        prefix, ep = net.worker_args(0)
        forger.append(subprocess.Popen([*prefix, sys.executable, __file__, "--forge", ep, coord.run_id],
                                       cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)),
                                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
    elif kind == "partition":
        if net.hosts is None:
            return None
        net.cut(True)
        counts[kind] += 1
        return now + PARTITION_S
    counts[kind] += 1
    return None


# Faults done at least once (also in a short soak): at this fraction of the planned time, or of the run's
# rows finished if the run goes faster than planned (so a run that ends early still gets each of them).
ONCE = {"forge": (0.2, 0.2), "coordinator_kill": (0.35, 0.35), "partition": (0.5, 0.5)}
# Once, a worker is frozen a few seconds before the run ends and woken when it is done: once the
# coordinator is gone nobody could tell it the run ended, so the coordinator must wait for it. "A few
# seconds" comes from the coordinator's ETA (longer than the worker's 2 s transport lease, so it is gone,
# not live, when the run ends), from half way on; at 90 % of the rows in any case.
END_STOP_ETA_S = 10.0


def due_once(pending: set[str], elapsed_frac: float, progress: float) -> list[str]:
    """Which of the once-only faults still pending are due."""
    return [k for k in ONCE if k in pending and (elapsed_frac >= ONCE[k][0] or progress >= ONCE[k][1])]


def end_stop_due(progress: float, eta_s: float | None) -> bool:
    return progress >= 0.9 or (progress >= 0.5 and eta_s is not None and eta_s <= END_STOP_ETA_S)


def run_state(path: Path) -> tuple[bool, float, float | None]:
    """(the run is done, the fraction of its planned rows finished, its ETA in s) from the coordinator's status
    file."""
    from spinefarm.storage.status import read_status

    st = read_status(path) or {}
    finished = int(st.get("trials_complete", 0)) + int(st.get("trials_failed", 0))
    eta = st.get("eta_s")
    return (st.get("state") == "done", finished / max(1, int(st.get("trials_planned", 0) or 1)),
            float(eta) if isinstance(eta, (int, float)) else None)


def drive(coord: Proc, workers: list[Proc], net: Net, minutes: float, seed: int, path: Path) -> dict:
    """Run the fault schedule until the coordinator exits 0 (the run is done), restarting whatever dies."""
    rng = random.Random(seed)
    t0 = time.monotonic()
    hard_end = t0 + 60.0 * minutes * 4 + 300.0
    once = {*ONCE, "end_stop"}
    next_fault = t0 + rng.uniform(2.0, 5.0)
    counts: Counter = Counter(unexpected_coordinator_exits=0, unexpected_worker_exits=0)
    forger: list = []
    heal_at: float | None = None
    coordinator_restarts = worker_restarts = 0
    while True:
        now = time.monotonic()
        code = coord.proc.poll()
        if code == 0:
            break
        if code is not None:
            counts["unexpected_coordinator_exits"] += coord.restart()
            coordinator_restarts += 1
        done, progress, eta_s = run_state(path)
        for w in workers:
            w.resume_if_due(now, force=done)  # frozen workers hear "done" before the coordinator leaves
            code = w.proc.poll()
            if code == 0 and not w.killed:  # told the run is over: restarted only if it is not, 10 s on
                w.exited_at = w.exited_at or now
            if code is not None and not done and (code != 0 or w.killed or now - w.exited_at > 10.0):
                counts["unexpected_worker_exits"] += w.restart()
                worker_restarts += 1
                w.exited_at = 0.0
        if heal_at is not None and (now >= heal_at or done):  # a run over while cut off: heal at once
            net.cut(False)
            heal_at = None
        due = due_once(once, (now - t0) / (60.0 * minutes), progress)
        for kind in due + (["end_stop"] if "end_stop" in once and not done and end_stop_due(progress, eta_s) else []):
            heal_at = inject(kind, rng, coord, workers, net, now, counts, forger) or heal_at
            once.discard(kind)
        if now >= next_fault:  # faults until the run is over
            kind = rng.choices(["worker_kill", "worker_stop", "coordinator_kill"], [3, 3, 1])[0]
            inject(kind, rng, coord, workers, net, now, counts, forger)
            next_fault = now + rng.uniform(4.0, 10.0)
        if now > hard_end:
            return {"timed_out": True, "faults": dict(counts)}
        time.sleep(0.05)
    if heal_at is not None:
        net.cut(False)
    for p in forger:
        p.wait(60)
    return {"timed_out": False, "wall_s": round(time.monotonic() - t0, 1), "faults": dict(counts),
            "coordinator_restarts": coordinator_restarts, "worker_restarts": worker_restarts}


def finish(workers: list[Proc], timeout_s: float = COORDINATOR_TIMEOUT_S + 30.0) -> tuple[list[str], float]:
    """Once the run is over every worker must exit by itself: the names of those that did not, and the
    seconds until the last one exited."""
    t0 = time.monotonic()
    for w in workers:
        w.resume_if_due(0.0, force=True)
    end = t0 + timeout_s
    while time.monotonic() < end and any(w.proc.poll() is None for w in workers):
        time.sleep(0.1)
    waited_s = time.monotonic() - t0
    hung = [w.name for w in workers if w.proc.poll() is None]
    for w in workers:
        if w.proc.poll() is None:
            w.proc.kill()
            w.proc.wait(10)
    return hung, waited_s


def silent_exits(workdir: Path) -> int:
    """Workers that ended by --coordinator-timeout (nobody told them the run was done), from their logs."""
    return sum(log.read_text(errors="replace").count("has been silent for") for log in workdir.glob("w*.log"))


def audit(path: Path, tmp: Path, budget: int) -> dict:
    """Lost, duplicated and forged, from the file against every acknowledgement the workers logged."""
    _, cols = read_run(path)
    status = [s.decode() for s in cols["status"]]
    stored: Counter = Counter()
    lost = 0
    for log in tmp.glob("acks-*.log"):
        for line in log.read_text().splitlines():
            _, tid, verdict, st, dist = line.split()
            if verdict != "stored":
                continue
            stored[int(tid)] += 1
            t = int(tid)
            same = t < len(status) and status[t] == st and (
                float(dist) == cols["distance_m"][t] or (math.isnan(float(dist)) and math.isnan(cols["distance_m"][t])))
            lost += not same
    reasons = [r.decode("utf-8", "replace") for r in cols["reason"]]
    checks = Counter(int(t) for t in read_evaluations(path)["trial_id"])
    forged = sum(1 for i, s in enumerate(status) if s == "complete" and (
        cols["distance_m"][i] == FORGED_M or cols["worker_id"][i] == b"forger"))
    return {"budget": budget, "parameter_sets": int((cols["rung"] == 0).sum()), "rows": len(status),
            "waiting": status.count("waiting"), "complete": status.count("complete"), "failed": status.count("failed"),
            "failed_timeout": sum(r.startswith("timeout:") for r in reasons),
            "failed_crashed": sum(r.startswith("crashed:") for r in reasons),
            "failed_lost_worker": sum(r.startswith("lost its worker") for r in reasons),
            "given_up_on_n_workers": distinct_workers(reasons),
            "failed_outside_bands": sum(1 for i, s in enumerate(status)
                                        if s == "failed" and cols["params_unit"][i, 0] >= POISON["crash"][1]),
            "acknowledged": sum(stored.values()), "lost": lost,
            # an audit's or a referee's result is acknowledged under the row it checked: one more "stored" each
            "duplicated": sum(max(0, c - 1 - checks[t]) for t, c in stored.items()), "forged_complete": forged,
            "exact_budget": int((cols["rung"] == 0).sum()) == budget and "waiting" not in status,
            **tasks_at_end(path, cols)}


def tasks_at_end(path: Path, cols: dict) -> dict:
    """Judges, audits and referees: how many ran (evaluation rows) and how many were left pending (should be 0)."""
    kinds = Counter(k.decode() for k in read_evaluations(path)["kind"])
    states = Counter(a.decode() for a in cols["audit"] if a)
    return {"judge_runs": kinds.get("judge", 0), "audit_runs": kinds.get("audit", 0),
            "referee_runs": kinds.get("referee", 0), "audit_states": dict(states),
            "tasks_pending_at_end": states.get("pending", 0) + states.get("disputed", 0)
            + int((cols["verification"] == b"pending").sum())}


def distinct_workers(reasons: list[str]) -> dict[str, int]:
    """How many given-up trials failed on 1, 2, 3 ... distinct workers (their reasons end "on N workers: ...")."""
    found = (re.search(r" on (\d+) workers?: ", r) for r in reasons)
    return dict(sorted(Counter(m.group(1) for m in found if m).items()))


def soak(minutes: float, seed: int, workdir: Path, netns: bool = True, rate: float = 3.5) -> dict:
    budget = max(40, int(minutes * 60 * rate))   # `rate` parameter sets per second under the faults
    path, run_id = workdir / "soak.h5", f"soak-{seed}"
    make_run(path, run_id, budget, seed)
    net = Net(netns)
    try:
        coord, workers = start_processes(net, path, run_id, workdir)
        try:
            out = drive(coord, workers, net, minutes, seed, path)
        finally:
            hung, exit_wait_s = finish(workers)
            if coord.proc.poll() is None:
                hung.append("coordinator")
                coord.proc.kill()
    finally:
        net.close()
    out.update(audit(path, workdir, budget))
    out.update({"minutes": minutes, "rate_sets_s": rate, "seed": seed, "workers": N_WORKERS, "rungs_s": list(RUNGS_S),
                "poison_bands": POISON, "hung_processes": hung, "workers_exit_s": round(exit_wait_s, 1),
                "workers_timed_out": silent_exits(workdir),
                "network": "namespaces" if net.hosts is not None else f"loopback (partition skipped: {net.why_not})"})
    return out


def main() -> None:
    from spinefarm.cli import checks  # an argparse type: seeds are whole numbers >= 0

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=30.0)
    ap.add_argument("--seed", type=checks.seed, default=1)
    ap.add_argument("--rate", type=float, default=3.5,
                    help="parameter sets a second the budget is sized for (3.5: 2 shared cores under heavy load)")
    ap.add_argument("--dir", type=Path, default=None, help="keep the run file and logs here")
    ap.add_argument("--no-netns", action="store_true", help="all on loopback, no partition")
    ap.add_argument("--forge", nargs=2, metavar=("ENDPOINT", "RUN_ID"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if not (args.rate > 0 and args.minutes > 0):
        ap.error(f"--minutes {args.minutes:g} --rate {args.rate:g}: expected both > 0")
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # a stopped soak still deletes its namespaces
    if args.forge:
        forge(args.forge[0], args.forge[1], 300)
        return
    if args.dir is not None:
        args.dir.mkdir(parents=True, exist_ok=True)
        print(json.dumps(soak(args.minutes, args.seed, args.dir, not args.no_netns, args.rate)))
        return
    with tempfile.TemporaryDirectory(prefix="spinefarm-soak-") as tmp:
        print(json.dumps(soak(args.minutes, args.seed, Path(tmp), not args.no_netns, args.rate)))


if __name__ == "__main__":
    main()
