"""Hundreds of workers against one coordinator, simulated: does it hold, and how fast does it grant?

Zenoh routers (`spinefarm router`, one per --sessions-per-router workers, meshed: a router here refuses its
352nd client session), one `spinefarm coordinator` connected to the first (test objective `sphere:4`
whose trials sleep --duration seconds, plus a random part of it up to --jitter, instead of simulating, so the
machine's cores go to the coordinator and the transport), and --workers workers, --per-process of them in
each worker process, each worker its own Zenoh session, worker id and identity (a real WorkerService in a
thread). Once a quarter of the budget is
stored and every worker is in (or half of it), --kill of the worker processes are SIGKILLed (whole processes,
so their sessions die as a machine's would). The run must still end with its exact budget. Workers start
--stagger seconds apart (hundreds of handshakes at once stall the router).

Every worker logs each verdict it receives (SPINEFARM_ACK_LOG) and each grant's round trip; the run file is
checked against the verdicts: `lost` (acknowledged as stored, not in the file or with another distance),
`duplicated` (acknowledged as stored twice). Latency is the worker's wait for its grant (a work query with
the results it carries), over every grant of every worker, the killed ones' until their kill.
`coordinator_rss_mb` is the coordinator's largest resident size, sampled every 0.5 s. The workers start once
the coordinator serves (its first status file). With SPINEFARM_GRANT_LOG the coordinator logs each work request's
arrival at its handler and the handler's time; `first_grant_split_ms` and `later_grants_split_ms` cut each grant's
wait in three on that one clock: `to_handler_ms` (the worker process, the routers, the coordinator's transport
thread and its queue), `in_handler_ms` (the core: its lock and work), `back_ms` (the reply to the worker's thread).
With --restart, once half the budget is stored the coordinator is SIGKILLed and resumed (`--resume`) --down-s
later, every worker still there: `restart_burst_ms` is the workers' wait for every grant in the --down-s + 20 s
after the kill (the resumed coordinator's start, its grace for workers to come back, the requests that meet it at
once), `restart_first_grant_ms` each worker's first grant from it, `restart_in_handler_ms` the handler's time over
that window.

usage: python bench/scale.py --workers 500 [--per-process 10] [--trials N] [--duration 10] [--jitter 0.5]
       [--kill 0.1] [--stagger 0.1] [--keep] [--restart [--down-s 0]]
prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
RUN_ID = "scale"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def host_workers(endpoint: str, first: int, count: int, out_dir: Path, stagger_s: float, duration_s: float,
                 jitter: float, join_step_s: float) -> None:
    """Child process: `count` workers, each in its own thread and Zenoh session, until the run says done. Once all
    its sessions are open it says so (ready-FIRST); once the bench says go, worker k asks for work k x join_step_s
    later (join_step_s < 0: each asks as soon as its session is open)."""
    os.environ["SPINEFARM_ACK_LOG"] = str(out_dir / f"acks-{first}.log")
    import logging

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(threadName)s %(levelname)s %(message)s")
    from spinefarm.protocol import keys
    from spinefarm.worker.service.zenoh_worker import WorkerService, WorkerTimings, ZenohAccess

    grants = open(out_dir / f"grants-{first}.log", "a", buffering=1)  # noqa: SIM115 (lives with the process)
    lock = threading.Lock()
    work_key = keys.work(RUN_ID)
    opened = [0]

    class TimedWorker(WorkerService):
        def _query(self, session, key, payload, cls):  # type: ignore[no-untyped-def]
            t0 = time.perf_counter()
            out = super()._query(session, key, payload, cls)
            if key == work_key and out[0]:
                with lock:
                    grants.write(f"{time.time():.4f} {1000 * (time.perf_counter() - t0):.3f} {self.worker_id}\n")
            return out

        def _loop(self, session):  # type: ignore[no-untyped-def]
            if join_step_s >= 0:
                with lock:
                    opened[0] += 1
                    if opened[0] == count:
                        (out_dir / f"ready-{first}").touch()
                while not (out_dir / "go").exists() and not self.stop.wait(0.05):
                    pass
                time.sleep(int(self.worker_id.split("-")[1]) * join_step_s)
            return super()._loop(session)

        def _run_one(self, evaluate, a):  # type: ignore[no-untyped-def]
            # trials of one length would keep every worker in step, asking at the same moment: real trial
            # times vary, so each takes a random extra part of its length
            time.sleep(random.uniform(0.0, jitter) * duration_s)
            return super()._run_one(evaluate, a)

    timings = WorkerTimings(coordinator_timeout_s=120.0)
    workers = [TimedWorker(ZenohAccess(connect=[endpoint]), run_id=RUN_ID, worker_id=f"sim-{first + i}", batch=1,
                           exit_when_done=True, isolate=False, timings=timings) for i in range(count)]
    threads = [threading.Thread(target=w.run, daemon=True) for w in workers]
    for t in threads:
        t.start()
        time.sleep(stagger_s)  # a connection storm of hundreds of handshakes at once stalls the router
    for t in threads:
        t.join()
    os._exit(0)  # Zenoh's threads can outlive the sessions: nothing is left to do


def _rss_mb(pid: int) -> float:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return 0.0


def _wait_listening(port: int, timeout_s: float = 30.0) -> None:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.1)
    raise SystemExit(f"nothing listens on port {port} after {timeout_s} s")


def _wait_serving(coord: subprocess.Popen, out: Path, timeout_s: float) -> None:
    """Until the coordinator writes its first status (it serves by then)."""
    end = time.monotonic() + timeout_s
    while not _status(out):
        if coord.poll() is not None or time.monotonic() > end:
            raise SystemExit(f"the coordinator did not start (rc {coord.poll()}); see {out.parent}/coordinator.log")
        time.sleep(0.2)


def _wait_files(tmp: Path, pattern: str, n: int, timeout_s: float) -> None:
    end = time.monotonic() + timeout_s
    while len(list(tmp.glob(pattern))) < n:
        if time.monotonic() > end:
            print(f"only {len(list(tmp.glob(pattern)))} of {n} worker processes ready after {timeout_s} s; going on",
                  file=sys.stderr)
            return
        time.sleep(0.5)


def _status(out: Path) -> dict:
    from spinefarm.storage.status import read_status

    return read_status(out) or {}


def _check(out: Path, tmp: Path) -> dict:
    """Stored rows against what the workers were told was stored."""
    from spinefarm.storage.hdf5 import Hdf5Storage

    with Hdf5Storage.open_read(out) as s:
        cols = s.columns()
    acked: dict[int, int] = {}
    lost = 0
    for path in tmp.glob("acks-*.log"):
        for line in path.read_text().splitlines():
            parts = line.split()
            if len(parts) != 5 or parts[2] != "stored":
                continue
            tid = int(parts[1])
            acked[tid] = acked.get(tid, 0) + 1
            same = tid < len(cols["status"]) and cols["status"][tid] == parts[3].encode() and (
                parts[3] != "complete" or repr(float(cols["distance_m"][tid])) == parts[4])
            lost += not same
    stored = int(np.count_nonzero(cols["status"] != b"waiting"))
    return {"rows": len(cols["status"]), "stored": stored, "acknowledged": len(acked), "lost": lost,
            "duplicated": sum(n - 1 for n in acked.values())}


def _percentiles(ms: np.ndarray) -> dict:
    return {"p50": round(float(np.percentile(ms, 50)), 2), "p99": round(float(np.percentile(ms, 99)), 2),
            "max": round(float(ms.max()), 2)} if len(ms) else {}


def _latencies(tmp: Path) -> dict:
    """Every grant's wait; apart, each worker's first (its session and routes just made) and the others."""
    rows = sorted(line.split() for p in tmp.glob("grants-*.log") for line in p.read_text().splitlines())
    t = np.array([float(r[0]) for r in rows])
    ms = np.array([float(r[1]) for r in rows])
    first = np.zeros(len(rows), bool)
    first[list({r[2]: i for i, r in reversed(list(enumerate(rows)))}.values())] = True
    span = float(t.max() - t.min()) if len(t) > 1 else math.nan
    return {"grants": len(ms), "workers_granted": int(first.sum()),
            "grants_per_s": round(len(ms) / span, 1) if span > 0 else None,
            "grant_latency_ms": _percentiles(ms), "first_grant_ms": _percentiles(ms[first]),
            "later_grants_ms": _percentiles(ms[~first])}


def _split(tmp: Path) -> dict:
    """Each grant's wait cut in three with the coordinator's own log (SPINEFARM_GRANT_LOG, same clock): on the way
    to the coordinator's handler (the worker process, the routers, the coordinator's Zenoh threads and GIL), in
    its handler (the core's lock and work), and back. The first and last parts are where the clients' own
    scheduling on a shared machine shows; the middle one is the coordinator's."""
    handled: dict[str, list[tuple[float, float]]] = {}
    for line in (tmp / "coordinator-grants.log").read_text().splitlines():
        t, ms, wid = line.split()
        handled.setdefault(wid, []).append((float(t), float(ms)))
    parts: dict[str, list[float]] = {"to_handler_ms": [], "in_handler_ms": [], "back_ms": []}
    firsts: dict[str, list[float]] = {k: [] for k in parts}
    seen: set[str] = set()
    for p in tmp.glob("grants-*.log"):
        for line in sorted(p.read_text().splitlines()):
            recv_s, ms, wid = line.split()
            end, start = float(recv_s), float(recv_s) - float(ms) / 1000
            match = [(t, h) for t, h in handled.get(wid, ()) if start - 0.002 <= t <= end]
            if not match:
                continue
            t, h = match[-1]
            split = {"to_handler_ms": 1000 * (t - start), "in_handler_ms": h, "back_ms": 1000 * (end - t) - h}
            for k, v in split.items():
                (parts if wid in seen else firsts)[k].append(max(v, 0.0))
            seen.add(wid)
    return {"first_grant_split_ms": {k: _percentiles(np.array(v)) for k, v in firsts.items()},
            "later_grants_split_ms": {k: _percentiles(np.array(v)) for k, v in parts.items()}}


def _restart(coord: subprocess.Popen, out: Path, endpoint: str, tmp: Path, down_s: float) -> subprocess.Popen:
    """--restart: SIGKILL the coordinator and resume its run file `down_s` later, every worker still waiting."""
    coord.send_signal(signal.SIGKILL)
    coord.wait(30)
    time.sleep(down_s)
    return _spinefarm("coordinator", "--resume", str(out), "--connect", endpoint, "--api-port", "-1", "--quiet",
                      log=tmp / "coordinator-resumed.log",
                      env={**os.environ, "SPINEFARM_GRANT_LOG": str(tmp / "coordinator-grants.log")})


def _burst(tmp: Path, killed_at: float, window_s: float = 20.0) -> dict:
    """The restart's burst: every grant the workers got in the `window_s` after the kill (--down-s + 20 s: the resumed
    coordinator's start, its grace for workers to come back and the re-asks after it), each worker's first grant
    from it apart, and the handler's time over the same window."""
    rows = sorted(line.split() for p in tmp.glob("grants-*.log") for line in p.read_text().splitlines())
    window = [(float(ms), wid) for t, ms, wid in rows if killed_at < float(t) <= killed_at + window_s]
    first: dict[str, float] = {}
    for ms, wid in window:
        first.setdefault(wid, ms)
    handled = [float(ms) for t, ms, _ in (line.split() for line in (tmp / "coordinator-grants.log").read_text()
                                           .splitlines()) if killed_at < float(t) <= killed_at + window_s]
    return {"restart_window_s": window_s, "restart_grants": len(window), "restart_workers_granted": len(first),
            "restart_burst_ms": _percentiles(np.array([ms for ms, _ in window])),
            "restart_first_grant_ms": _percentiles(np.array(list(first.values()))),
            "restart_in_handler_ms": _percentiles(np.array(handled))}


def _spinefarm(*args: str, log: Path, env: dict | None = None) -> subprocess.Popen:
    with open(log, "w") as fh:
        return subprocess.Popen([sys.executable, "-m", "spinefarm", *args], cwd=ROOT, stdout=subprocess.DEVNULL,
                                stderr=fh, env=env)


def _routers(tmp: Path, workers: int, per_router: int) -> tuple[list[subprocess.Popen], list[str]]:
    """Enough meshed routers for the workers: the first one listens, the others connect to it. One Zenoh 1.10
    router here refuses the 352nd client session (accept_pending and max_sessions raised or not)."""
    procs, endpoints = [], []
    for i in range(max(1, math.ceil(workers / per_router))):
        port = free_port()
        endpoints.append(f"tcp/127.0.0.1:{port}")
        conf = {"transport": {"unicast": {"accept_pending": 4 * per_router, "accept_timeout": 30000}}}
        if i:
            conf["connect"] = {"endpoints": endpoints[:1]}
        (tmp / f"router-{i}.json5").write_text(json.dumps(conf))
        procs.append(_spinefarm("router", "--listen", endpoints[-1], "--config", str(tmp / f"router-{i}.json5"),
                                log=tmp / f"router-{i}.log"))
        _wait_listening(port)
    return procs, endpoints


def run(args: argparse.Namespace) -> dict:
    tmp = Path(tempfile.mkdtemp(prefix="spinefarm-scale-", dir=args.dir))
    out = tmp / "run.h5"
    trials = args.trials or 6 * args.workers
    procs: list[subprocess.Popen] = []
    routers: list[subprocess.Popen] = []
    try:
        routers, endpoints = _routers(tmp, args.workers, args.sessions_per_router)
        coord = _spinefarm("coordinator", "sphere:4", "--trials", str(trials), "--duration", str(args.duration),
                           "--run-id", RUN_ID, "--out", str(out), "--connect", endpoints[0], "--api-port", "-1",
                           "--quiet", "--sampler", "random", log=tmp / "coordinator.log",
                           env={**os.environ, "SPINEFARM_GRANT_LOG": str(tmp / "coordinator-grants.log")})
        # workers join a coordinator that serves (a farm's usual case). Started together, the 50 worker processes'
        # imports starved the coordinator's start for over a minute on 2 cores; every worker was in and asking by
        # then, and 500 first requests within 2 s queued ~0.5 s at its one transport thread (about 1 ms each).
        _wait_serving(coord, out, args.timeout_s)
        per = args.per_process
        for first in range(0, args.workers, per):
            endpoint = endpoints[(first // per) % len(endpoints)]
            procs.append(subprocess.Popen([sys.executable, __file__, "--host", endpoint, "--first", str(first),
                                           "--count", str(min(per, args.workers - first)), "--dir", str(tmp),
                                           "--stagger", str(args.stagger), "--duration", str(args.duration),
                                           "--jitter", str(args.jitter), "--join-step",
                                           str(args.join_s / args.workers if args.join_s >= 0 else -1.0)],
                                          cwd=ROOT, stdout=subprocess.DEVNULL,
                                          stderr=open(tmp / f"host-{first}.log", "w")))  # noqa: SIM115
            time.sleep(args.stagger)
        if args.join_s >= 0:
            _wait_files(tmp, "ready-*", len(procs), args.timeout_s)
            (tmp / "go").touch()
        killed, rss, t0, restarted_at = 0, 0.0, time.monotonic(), None
        n_kill = math.ceil(args.kill * len(procs))
        while coord.poll() is None:
            if time.monotonic() - t0 > args.timeout_s:
                raise SystemExit(f"the run did not end within {args.timeout_s} s; files in {tmp}")
            rss = max(rss, _rss_mb(coord.pid))
            st = _status(out)
            seen = len(st.get("workers", []))
            # the kill comes once every worker is in (or half the budget is stored, whichever is first)
            if not killed and st.get("trials_complete", 0) >= trials // 4 and (
                    seen >= args.workers or st.get("trials_complete", 0) >= trials // 2):
                for p in procs[-n_kill:] if n_kill else []:
                    p.send_signal(signal.SIGKILL)
                killed = n_kill or -1
            if args.restart and killed and restarted_at is None and st.get("trials_complete", 0) >= trials // 2:
                restarted_at = time.time()
                coord = _restart(coord, out, endpoints[0], tmp, args.down_s)
            time.sleep(0.5)
        wall_s = time.monotonic() - t0
        late = 0
        for p in procs:  # a worker that connects after the coordinator left waits out its timeout: not for us
            try:
                p.wait(max(1.0, 15.0 - (time.monotonic() - t0 - wall_s)))
            except subprocess.TimeoutExpired:
                p.kill()
                late += 1
        checked = _check(out, tmp)
        result = {"workers": args.workers, "trials": trials, "stored": checked["stored"], "lost": checked["lost"],
                "duplicated": checked["duplicated"], **_latencies(tmp), **_split(tmp),
                **({} if restarted_at is None else _burst(tmp, restarted_at, args.down_s + 20.0)),
                "coordinator_rss_mb": round(rss, 1),
                "exact_budget": checked["rows"] == trials and checked["stored"] == trials,
                "acknowledged": checked["acknowledged"], "workers_killed": sum(
                    min(per, args.workers - i * per) for i in range(len(procs) - max(killed, 0), len(procs))),
                "worker_processes": len(procs), "per_process": per, "duration_s": args.duration,
                "processes_left_after_the_run": late, "routers": len(routers), "jitter": args.jitter,
                "join_s": args.join_s,
                "coordinator_rc": coord.returncode, "wall_s": round(wall_s, 1), "dir": str(tmp)}
        if result["exact_budget"] and not (result["lost"] or result["duplicated"]) and not args.keep:
            shutil.rmtree(tmp)   # a run that holds leaves nothing behind; one that does not keeps its files
            result["dir"] = None
        return result
    finally:
        for p in [*procs, *routers]:
            if p.poll() is None:
                p.kill()
                p.wait(10)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=500)
    ap.add_argument("--per-process", type=int, default=10, help="workers per worker process (default 10)")
    ap.add_argument("--trials", type=int, default=0, help="budget (default 6 per worker)")
    ap.add_argument("--duration", type=float, default=10.0, help="seconds each trial sleeps (default 10: a physics "
                    "trial's wall time)")
    ap.add_argument("--jitter", type=float, default=0.5, help="each trial also sleeps a uniform random part of "
                    "[0, jitter] of --duration (default 0.5)")
    ap.add_argument("--sessions-per-router", type=int, default=300, help="workers per Zenoh router (default 300: "
                    "a router here refuses its 352nd session); several routers are meshed")
    ap.add_argument("--kill", type=float, default=0.1, help="fraction of the worker processes SIGKILLed")
    ap.add_argument("--timeout-s", type=float, default=1200.0)
    ap.add_argument("--dir", default=None, help="where the run's files go (default: the temp directory)")
    ap.add_argument("--stagger", type=float, default=0.1, help="seconds between two workers' starts in a process "
                    "and between two processes' (default 0.1)")
    ap.add_argument("--keep", action="store_true", help="keep the run's files even when it holds")
    ap.add_argument("--join-s", type=float, default=10.0, help="once every worker process has started and opened "
                    "its sessions, the workers start asking for work over this many seconds, evenly (default 10); "
                    "-1: each asks as soon as its session is open, while the other processes start")
    ap.add_argument("--restart", action="store_true", help="once half the budget is stored (after the workers' "
                    "kill), SIGKILL the coordinator and resume its run with every worker waiting; prints the burst "
                    "of first grants from the resumed one (restart_burst_ms)")
    ap.add_argument("--down-s", type=float, default=0.0, help="with --restart: seconds between the kill and the "
                    "resume (default 0; 10 lets every waiting worker reach its longest back-off)")
    ap.add_argument("--join-step", type=float, default=-1.0, help=argparse.SUPPRESS)
    ap.add_argument("--host", help=argparse.SUPPRESS)
    ap.add_argument("--first", type=int, default=0, help=argparse.SUPPRESS)
    ap.add_argument("--count", type=int, default=0, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.host:
        host_workers(args.host, args.first, args.count, Path(args.dir), args.stagger, args.duration, args.jitter,
                     args.join_step)
        return
    print(json.dumps(run(args)))


if __name__ == "__main__":
    main()
