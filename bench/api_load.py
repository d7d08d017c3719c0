"""`spinefarm api --runs-dir` under many concurrent readers while a search writes one of its runs.

    python bench/api_load.py [--connections 200] [--seconds 20] [--finished 2] [--busy 0]

Starts a live search (`spinefarm search sphere:3`, one local worker, a budget it will not reach) and `--finished`
short finished searches in one folder, serves the folder with `spinefarm api --runs-dir`, then keeps
`--connections` connections busy from the start (before the server has read any file) for `--seconds`, each
asking GET /runs and GET /runs/{id} in turn. `--busy N` adds N busy loops (a loaded machine).

Prints one JSON object: requests and their status codes (or the client's error), `runs_dropped` (responses to
/runs that left out a run, and 404s for a run: every file is good and there before the server starts),
`server_errors` (5xx), `every_run_listed` (some response listed them all), latency p50/p99 in ms, requests per
second and the machine's load average. The target: 0 runs dropped, 0 server errors, every run listed.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import httpx
import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def spinefarm(*args: str, wait: bool = True) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, "-m", "spinefarm", *args], cwd=ROOT, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    if wait and proc.wait(600) != 0:
        raise SystemExit(f"spinefarm {' '.join(args)} failed")
    return proc


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


async def reader(client: httpx.AsyncClient, ids: list[str], until: float, tally: dict) -> None:
    i = 0
    while time.monotonic() < until:
        for path in ("/runs", f"/runs/{ids[i % len(ids)]}"):
            t0 = time.perf_counter()
            try:
                r = await client.get(path)
            except httpx.HTTPError as exc:
                tally["codes"][type(exc).__name__] += 1
                continue
            tally["latency_s"].append(time.perf_counter() - t0)
            tally["codes"][r.status_code] += 1
            if r.status_code == 200 and path == "/runs":
                listed = {x["run_id"] for x in r.json()}
                tally["dropped"] += listed != set(ids)  # every run's file was good before the server started
                tally["all_seen"] = tally["all_seen"] or listed == set(ids)
            elif r.status_code == 404:
                tally["dropped"] += 1
        i += 1


async def load(url: str, ids: list[str], connections: int, seconds: float) -> dict:
    tally = {"codes": Counter(), "latency_s": [], "dropped": 0, "all_seen": False}
    limits = httpx.Limits(max_connections=connections, max_keepalive_connections=connections)
    async with httpx.AsyncClient(base_url=url, timeout=120, limits=limits) as client:
        until = time.monotonic() + seconds
        t0 = time.perf_counter()
        await asyncio.gather(*(reader(client, ids, until, tally) for _ in range(connections)))
        elapsed = time.perf_counter() - t0
    lat = np.asarray(tally["latency_s"]) * 1e3
    codes = {str(k): v for k, v in sorted(tally["codes"].items(), key=str)}
    return {"requests": int(lat.size), "status": codes, "runs_dropped": tally["dropped"],
            "server_errors": sum(v for k, v in tally["codes"].items() if isinstance(k, int) and k >= 500),
            "every_run_listed": tally["all_seen"], "latency_ms": {"p50": float(np.percentile(lat, 50)),
                                                                  "p99": float(np.percentile(lat, 99))},
            "requests_per_s": lat.size / elapsed}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--connections", type=int, default=200)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--finished", type=int, default=2)
    ap.add_argument("--busy", type=int, default=0)
    args = ap.parse_args()
    procs: list[subprocess.Popen] = []
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        ids = [f"finished-{i}" for i in range(args.finished)] + ["live"]
        try:
            for run_id in ids[:-1]:
                spinefarm("search", "sphere:3", "--trials", "40", "--workers", "1", "--run-id", run_id, "--out",
                          str(d / f"{run_id}.h5"), "--api-port", "-1", "--quiet")
            procs.append(spinefarm("search", "sphere:3", "--trials", "100000000", "--workers", "1", "--run-id",
                                   "live", "--out", str(d / "live.h5"), "--api-port", "-1", "--quiet", wait=False))
            while not (d / "live.h5.status.json").exists():
                time.sleep(0.1)
            procs += [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.busy)]
            port = free_port()
            procs.append(spinefarm("api", "--runs-dir", str(d), "--port", str(port), wait=False))
            url = f"http://127.0.0.1:{port}"
            while True:
                try:
                    if httpx.get(url + "/health", timeout=1).status_code == 200:
                        break
                except httpx.HTTPError:
                    time.sleep(0.1)
            figures = asyncio.run(load(url, sorted(ids), args.connections, args.seconds))
        finally:
            for p in reversed(procs):
                p.terminate()
                p.wait(60)
    print(json.dumps({"benchmark": "api_load", "connections": args.connections, "seconds": args.seconds,
                      "runs": len(ids), "live_runs": 1, "busy_loops": args.busy,
                      "load_average_1min": os.getloadavg()[0], **figures}))


if __name__ == "__main__":
    main()
