"""Several good run files served by `spinefarm api --runs-dir` while the machine is busy (busy loops on every core)
and many requests arrive at once from the start: every response lists every run, none is ever a 404 or a 5xx."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from collections import Counter

import httpx

from tests.api_tests.test_damaged_files import _ok, run_file
from tests.coordinator_tests.helpers import wait_for
from tests.coordinator_tests.procs import ROOT

FILES = 6
CLIENTS = 24
HAMMER_S = 8.0


def busy_loops(n: int) -> list[subprocess.Popen]:
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]


def hammer(url: str, ids: list[str], until: float, seen: Counter, missing: list, lock: threading.Lock) -> None:
    with httpx.Client(base_url=url, timeout=120) as client:
        i = 0
        while time.monotonic() < until:
            r = client.get("/runs")
            listed = sorted(x["run_id"] for x in r.json()) if r.status_code == 200 else []
            one = client.get(f"/runs/{ids[i % len(ids)]}")
            with lock:
                seen[r.status_code] += 1
                seen[one.status_code] += 1
                if listed != ids:
                    missing.append(sorted(set(ids) - set(listed)))
            i += 1


def test_every_good_file_is_served_under_cpu_load_and_concurrent_requests(tmp_path):
    from spinefarm.cli.service_commands import free_port

    d = tmp_path / "runs"
    d.mkdir()
    ids = sorted(f"run-{i}" for i in range(FILES))
    for run_id in ids:
        run_file(d / f"{run_id}.h5", run_id)
    port = free_port()
    loops = busy_loops(2 * (os.cpu_count() or 2))
    proc = subprocess.Popen([sys.executable, "-m", "spinefarm", "api", "--runs-dir", str(d), "--port", str(port)],
                            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        url = f"http://127.0.0.1:{port}"
        wait_for(lambda: _ok(url + "/health"), timeout_s=120, what="the API")
        seen: Counter = Counter()
        missing: list = []
        lock = threading.Lock()
        until = time.monotonic() + HAMMER_S
        threads = [threading.Thread(target=hammer, args=(url, ids, until, seen, missing, lock))
                   for _ in range(CLIENTS)]  # all at once, before the server has read any file
        for t in threads:
            t.start()
        for t in threads:
            t.join(300)
    finally:
        for p in loops:
            p.kill()
            p.wait()
        proc.terminate()
        proc.wait(30)
    assert set(seen) == {200} and seen[200] >= 2 * CLIENTS, (seen, proc.stderr.read()[-2000:])
    assert not missing, f"{len(missing)} responses left out runs, e.g. {missing[:3]}"
