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


# The probe's reading child, its read slowed to 8 s (past the first deadline of 5 s) while RUN.h5.slow exists.
SLOW_WHILE_MARKED = """
import sys
import spinefarm.storage.probe as probe
READ = "try:\\n"  # the read, after the child has started
probe._PROBE_CODE = probe._PROBE_CODE.replace(READ, (
    "import os, time\\n"
    "if os.path.exists(sys.argv[1] + '.slow'):\\n"
    "    time.sleep(8)\\n") + READ, 1)
"""


def test_a_good_file_replaced_and_read_again_slowly_stays_served(tmp_path):
    """Resume and compress-at-close replace a run file: its new read may run out of time on a busy machine;
    meanwhile the run is "still reading" with its last good state, never missing."""
    import shutil

    from spinefarm.cli.service_commands import free_port

    d = tmp_path / "runs"
    d.mkdir()
    run_file(d / "kept.h5", "kept")
    port = free_port()
    args = ["api", "--runs-dir", str(d), "--port", str(port)]
    proc = subprocess.Popen([sys.executable, "-c", SLOW_WHILE_MARKED + "from spinefarm.cli.main import main\n"
                             f"sys.exit(main({args!r}))"], cwd=ROOT, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    try:
        url = f"http://127.0.0.1:{port}"
        wait_for(lambda: _ok(url + "/health"), timeout_s=60, what="the API")
        assert [r["run_id"] for r in httpx.get(url + "/runs", timeout=60).json()] == ["kept"]
        (d / "kept.h5.slow").touch()
        shutil.copy(d / "kept.h5", tmp_path / "copy.h5")
        os.replace(tmp_path / "copy.h5", d / "kept.h5")  # a new inode: read again, slowly
        end = time.monotonic() + 12
        while time.monotonic() < end:
            assert [r["run_id"] for r in httpx.get(url + "/runs", timeout=30).json()] == ["kept"]
            assert httpx.get(url + "/runs/kept", timeout=30).status_code == 200
            time.sleep(0.3)
    finally:
        proc.terminate()
        proc.wait(30)
    err = proc.stderr.read()
    assert "still reading" in err and "did not finish within 5 s" in err, err[-2000:]
