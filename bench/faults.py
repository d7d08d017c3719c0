"""The fault suite as figures: kills survived, acknowledged trials lost or duplicated, re-issue latency,
forged and malformed messages rejected, a full disk, a disk that dies mid-run (as in a power cut),
damaged files.

Real processes, real Zenoh on loopback, real HDF5 files. Workers here are "witness" workers
(bench/fault_witness.py): they speak the real protocol and log every result the coordinator acknowledged as
stored, so "lost" means acknowledged but absent from the file and "duplicated" means acknowledged as stored twice.

Prints one JSON object per part; the last line is one JSON object with everything.
usage: python bench/faults.py [--runs 4] [--trials 300] [--seed 1] [--power-cuts 1] [--skip disk,power_cut]
"""

from __future__ import annotations

import argparse
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.fault_witness import acked, check_file, coordinator, spawn, wait, witness  # noqa: E402
from spinefarm.cli.service_commands import free_port  # noqa: E402
from spinefarm.protocol import keys  # noqa: E402


# --- parts ---------------------------------------------------------------------------------------------
def kill_matrix(runs: int, trials: int, seed: int, tmp: Path) -> dict:
    """Random SIGKILLs of a worker, of the coordinator, or of all of them at once, until each run ends."""
    rng = random.Random(seed)
    totals = {"runs": runs, "worker_kills": 0, "coordinator_kills": 0, "group_kills": 0, "lost": 0,
              "duplicated": 0, "runs_at_exact_budget": 0, "acknowledged": 0}
    for r in range(runs):
        _kill_run(f"kill{r}", trials, rng, tmp, totals)
    totals["kills_survived"] = totals["worker_kills"] + totals["coordinator_kills"] + totals["group_kills"]
    return totals


def _kill_run(run_id: str, trials: int, rng: random.Random, tmp: Path, totals: dict) -> None:
    ep, out = f"tcp/127.0.0.1:{free_port()}", tmp / f"{run_id}.h5"
    logs: list[Path] = []

    def new_witness() -> subprocess.Popen:
        logs.append(tmp / f"{run_id}-w{len(logs)}.jsonl")
        return witness(ep, run_id, f"w{len(logs)}", logs[-1])

    def start_coordinator() -> subprocess.Popen:
        c = coordinator(ep, out, *(("sphere:4", "--trials", str(trials), "--duration", "0.01", "--run-id",
                                    run_id, "--lease", "5") if not out.exists() else ()))
        lock = out.with_name(out.name + ".lock")  # holds the writer's pid once it owns the file
        wait(lambda: c.poll() is not None or (out.exists() and lock.exists()
                                              and lock.read_text().strip() == str(c.pid)), 60, "the coordinator")
        return c

    def start_all() -> tuple[subprocess.Popen, list[subprocess.Popen]]:
        return start_coordinator(), [new_witness() for _ in range(3)]

    coord, ws = start_all()
    end = time.monotonic() + 240
    while coord.poll() is None and time.monotonic() < end:
        time.sleep(rng.uniform(0.3, 1.2))
        if coord.poll() is not None:
            break
        what = rng.random()
        if what < 0.6:
            i = rng.randrange(len(ws))
            ws[i].send_signal(signal.SIGKILL)
            ws[i].wait()
            ws[i] = new_witness()
            totals["worker_kills"] += 1
        elif what < 0.9:
            coord.send_signal(signal.SIGKILL)
            coord.wait()
            coord = start_coordinator()  # resume; the workers keep their unacknowledged results
            totals["coordinator_kills"] += 1
        else:
            for p in (coord, *ws):  # everything at once, as a killed process group
                p.send_signal(signal.SIGKILL)
            for p in (coord, *ws):
                p.wait()
            totals["group_kills"] += 1
            coord, ws = start_all()
    rc = coord.wait(60)
    for w in ws:
        try:
            w.wait(30)
        except subprocess.TimeoutExpired:
            w.kill()
    f = check_file(out, trials, acked(logs))
    totals["lost"] += f["lost"]
    totals["duplicated"] += f["duplicated"]
    totals["acknowledged"] += f["acknowledged"]
    totals["runs_at_exact_budget"] += int(rc == 0 and f["rows"] == trials and f["complete"] == trials)


def reissue_latency(tmp: Path, repeats: int = 3) -> dict:
    """SIGSTOP a worker holding a lease: seconds until the coordinator re-issues its trial."""
    return {"reissue_latency_s": [round(_one_reissue(f"ri{k}", tmp), 2) for k in range(repeats)],
            "worker_transport_lease_s": 2.0, "lease_s": 60.0}


def _one_reissue(run_id: str, tmp: Path) -> float:
    from spinefarm.coordinator.problem import build_run_config
    from spinefarm.coordinator.service import CoordinatorService
    from spinefarm.coordinator.setup import SearchSettings, new_run

    ep = f"tcp/127.0.0.1:{free_port()}"
    core, storage = new_run(build_run_config(run_id, "sphere:4", duration_s=1.0),
                            SearchSettings(trials=50, lease_s=60.0), tmp / f"{run_id}.h5")
    service = CoordinatorService(core, storage, listen=[ep]).start()
    w = spawn("-m", "spinefarm", "worker", "--connect", ep, "--run", run_id, "--batch", "1")
    try:
        wait(lambda: core.scheduler.n_leased > 0, 30, "a lease")
        w.send_signal(signal.SIGSTOP)
        t0 = time.monotonic()
        wait(lambda: core.scheduler.reissued > 0, 30, "the re-issue")
        return time.monotonic() - t0
    finally:
        w.send_signal(signal.SIGCONT)
        w.kill()
        w.wait()
        service.close()


def hostile_peer(tmp: Path, n: int = 500) -> dict:
    """A peer that knows a real worker's id sends forged results and malformed messages."""
    import zenoh

    from spinefarm.coordinator.problem import build_run_config
    from spinefarm.coordinator.service import CoordinatorService, zenoh_config
    from spinefarm.coordinator.setup import SearchSettings, new_run
    from spinefarm.protocol.envelope import SCHEMA_VERSION, decode, encode_message
    from spinefarm.protocol.results import TrialResult
    from spinefarm.protocol.states import TrialStatus
    from spinefarm.protocol.submissions import ResultSubmission, SubmittedResult

    ep = f"tcp/127.0.0.1:{free_port()}"
    core, storage = new_run(build_run_config("hostile", "sphere:4", duration_s=2.0),
                            SearchSettings(trials=20, lease_s=60.0), tmp / "hostile.h5")
    service = CoordinatorService(core, storage, listen=[ep]).start()
    honest = spawn("-m", "spinefarm", "worker", "--connect", ep, "--run", "hostile", "--batch", "4",
                   "--worker-id", "honest")
    s = None
    try:
        wait(lambda: core.scheduler.n_leased > 0, 30, "the honest worker's leases")
        s = zenoh.open(zenoh_config("client", connect=[ep]))
        rng = random.Random(7)
        leased = [t for t in range(core.study.storage.n_trials()) if core.scheduler.lease_of(t)]
        error_replies = 0
        for _ in range(n):
            tid = rng.choice(leased)
            forged = TrialResult(TrialStatus.COMPLETE, "", 1237.0, 0, 0, 0, 0, 1, 1, 1,
                                 int(core.study.storage.columns()["seed"][tid]), trial_id=tid, worker_id="honest")
            # it names the run's instance (every grant says it): only the lease can give it away
            sub = ResultSubmission("honest", (SubmittedResult(rng.getrandbits(62), forged, coordinator=core.holder),))
            list(s.get(keys.results("hostile"), payload=encode_message(sub), timeout=5.0))
        corpus = [b"[" * 50_000, b'{"schema":1,"kind":"work_request","body":{"worker_id":"w","capacity":' +
                  b"9" * 5000 + b"}}", b'{"schema":1,"kind":"work_request","body":{"worker_id":"w","capacity":1e400}}',
                  json.dumps({"schema": SCHEMA_VERSION, "kind": "work_request",
                              "body": {"worker_id": "\ud800", "capacity": 1}}).encode(),
                  json.dumps({"schema": SCHEMA_VERSION, "kind": "work_request",
                              "body": {"worker_id": "x" * 100_000, "capacity": 1}}).encode(),
                  b"\xff\xfe", b"null", b'{"schema":1}']
        for i in range(n):
            for r in s.get(keys.work("hostile"), payload=corpus[i % len(corpus)], timeout=5.0):
                if r.ok and decode(r.ok.payload.to_bytes())[0] == "error":
                    error_replies += 1
        import numpy as np

        best = float(np.nanmax(np.where(core.study.storage.columns()["status"] == b"complete",
                                        core.study.storage.columns()["distance_m"], np.nan))) \
            if core.study.storage.counts()["complete"] else None
        st = core.status()
        return {"forged_sent": n, "forged_rejected": st["forged_results"], "malformed_sent": n,
                "malformed_error_replies": error_replies, "malformed_rejected": st["rejected_messages"],
                "forged_best_stored": best is not None and best >= 1237.0}
    finally:
        if s is not None:
            s.close()
        honest.kill()
        honest.wait()
        service.close()


def full_disk(tmp: Path) -> dict:
    """A coordinator writing to a 1.2 MB tmpfs until it is full, with a witness worker."""
    mnt = tmp / "small"
    mnt.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1200k", "tmpfs", str(mnt)], capture_output=True).returncode:
        return {"skipped": "cannot mount a tmpfs (needs root)"}
    try:
        ep, out = f"tcp/127.0.0.1:{free_port()}", mnt / "run.h5"
        c = coordinator(ep, out, "sphere:8", "--trials", "1000000", "--run-id", "disk")
        log = tmp / "disk.jsonl"
        w = witness(ep, "disk", "wd", log)
        t0 = time.monotonic()
        rc = c.wait(180)
        err = c.stderr.read()
        w.kill()
        w.wait()
        f = check_file(out, 0, acked([log]))
        return {"exit_code": rc, "says_why": "No space left on device" in err, "seconds": time.monotonic() - t0,
                "acknowledged": f["acknowledged"], "lost": f["lost"], "rows_in_file": f["rows"],
                "segfault": "Segmentation" in err or rc == -11}
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def power_cut(tmp: Path, workers: int = 2, cut_after_acks: int = 300) -> dict:
    """The disk under a writing coordinator dies (a real ext4 on a loop device, shut down without
    flushing its journal, as a power cut); after a remount the file must hold every acknowledged result."""
    from tests.ext4_image import Ext4Image

    why = Ext4Image.unavailable()
    if why is not None:
        return {"skipped": why}
    (tmp / "powercut").mkdir()
    disk = Ext4Image(tmp / "powercut")
    try:
        disk.open()
    except RuntimeError as exc:
        return {"skipped": str(exc)}
    procs: list[subprocess.Popen] = []
    try:
        ep, out = f"tcp/127.0.0.1:{free_port()}", disk.mnt / "run.h5"
        c = coordinator(ep, out, "sphere:8", "--trials", "1000000", "--run-id", "powercut")
        logs = [tmp / f"powercut-w{i}.jsonl" for i in range(workers)]
        procs = [c, *(witness(ep, "powercut", f"pc{i}", log) for i, log in enumerate(logs))]
        wait(lambda: c.poll() is not None or len(acked(logs)) >= cut_after_acks, 60, "acknowledged results")
        t0 = time.monotonic()
        disk.shutdown()
        try:
            rc: int | None = c.wait(60)
        except subprocess.TimeoutExpired:
            rc = None  # a hang: killed so the disk can be remounted and checked
            c.kill()
            c.wait()
        seconds = time.monotonic() - t0
        err = c.stderr.read()
        for w in procs[1:]:
            w.kill()
            w.wait()
        disk.remount()  # journal replay: what a reboot finds
        f = check_file(out, 0, acked(logs))
        resumes = _resumes(out) if "unreadable" not in f else "unreadable"
        return {"exit_code": rc, "says_why": "Input/output error" in err, "seconds_to_exit": round(seconds, 2),
                "hung": rc is None, "acknowledged": f["acknowledged"], "lost": f["lost"],
                "duplicated": f["duplicated"], "rows_in_file": f["rows"], "complete_in_file": f["complete"],
                "resumes": resumes, **({"unreadable": f["unreadable"]} if "unreadable" in f else {}),
                "error": (err.strip().splitlines() or [""])[-1][:200]}
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()
        disk.close()


def _resumes(out: Path) -> str:
    """'yes' if the run reopens for writing as `--resume` would (every row validated), else the error."""
    from spinefarm.coordinator.setup import resume_run

    try:
        _, storage = resume_run(out)
    except Exception as exc:
        return str(exc)[:200]
    storage.close()
    return "yes"


def power_cuts(tmp: Path, tries: int) -> dict:
    """`power_cut` repeated: the first try's figures, and over all tries how many were lost."""
    first: dict = {}
    totals = {"tries": 0, "acknowledged": 0, "lost": 0, "duplicated": 0, "unreadable": 0, "not_resumable": 0,
              "hung": 0,
              "not_exit_code_1": 0, "max_seconds_to_exit": 0.0}
    for k in range(tries):
        d = tmp / f"cut{k}"
        d.mkdir()
        r = power_cut(d)
        if "skipped" in r:
            return r
        first = first or r
        totals["tries"] += 1
        for key in ("acknowledged", "lost", "duplicated"):
            totals[key] += r[key]
        totals["unreadable"] += int("unreadable" in r)
        totals["not_resumable"] += int(r["resumes"] != "yes")
        totals["hung"] += int(r["hung"])
        totals["not_exit_code_1"] += int(r["exit_code"] != 1 or not r["says_why"])
        totals["max_seconds_to_exit"] = max(totals["max_seconds_to_exit"], r["seconds_to_exit"])
    return {**first, "repeated": totals} if tries > 1 else first


def damaged_files(tmp: Path) -> dict:
    """Seconds until `search --resume` of a damaged file gives its error (never a hang)."""
    from tests.coordinator_tests.test_run_file_faults import finished_run

    src = tmp / "good.h5"
    finished_run(src)
    out = {}
    for name in ("truncated", "garbled_header", "second_writer"):
        p = tmp / f"{name}.h5"
        shutil.copy(src, p)
        holder = None
        if name == "truncated":
            os.truncate(p, p.stat().st_size // 2)
        elif name == "garbled_header":
            with open(p, "r+b") as fh:
                fh.seek(200)
                fh.write(b"\xff" * 512)
        else:
            holder = spawn("-c", "import fcntl,sys,time; f=open(sys.argv[1],'w'); fcntl.flock(f, fcntl.LOCK_EX); "
                           "print('held', flush=True); time.sleep(60)", str(p) + ".lock")
            time.sleep(0.5)
        t0 = time.monotonic()
        r = subprocess.run([sys.executable, "-m", "spinefarm", "search", "--resume", str(p), "--workers", "0",
                            "--api-port", "-1"], cwd=ROOT, capture_output=True, text=True, timeout=120)
        out[name] = {"exit_code": r.returncode, "seconds": round(time.monotonic() - t0, 2),
                     "error": r.stderr.strip().splitlines()[-1][:160] if r.stderr.strip() else ""}
        if holder is not None:
            holder.kill()
            holder.wait()
    return out


def main() -> None:
    import logging

    from spinefarm.cli import checks  # an argparse type: seeds are whole numbers >= 0

    logging.getLogger("spinefarm").setLevel(logging.ERROR)  # rejected messages are counted, not printed
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=4, help="runs of the kill matrix")
    ap.add_argument("--trials", type=int, default=300, help="trial budget of each kill-matrix run")
    ap.add_argument("--seed", type=checks.seed, default=1)
    ap.add_argument("--power-cuts", type=int, default=1, help="tries of the dying-disk part")
    ap.add_argument("--skip", default="",
                    help="comma-separated parts to skip: kills,reissue,hostile,disk,power_cut,files")
    args = ap.parse_args()
    skip = set(filter(None, args.skip.split(",")))
    results = {}
    with tempfile.TemporaryDirectory(prefix="spinefarm-faults-") as d:
        tmp = Path(d)
        parts = {"kills": lambda: kill_matrix(args.runs, args.trials, args.seed, tmp),
                 "reissue": lambda: reissue_latency(tmp), "hostile": lambda: hostile_peer(tmp),
                 "disk": lambda: full_disk(tmp), "power_cut": lambda: power_cuts(tmp, args.power_cuts),
                 "files": lambda: damaged_files(tmp)}
        for name, fn in parts.items():
            if name in skip:
                continue
            t0 = time.monotonic()
            results[name] = fn()
            results[name]["wall_s"] = round(time.monotonic() - t0, 1)
            print(json.dumps({name: results[name]}), flush=True)
    print(json.dumps(results))


if __name__ == "__main__":
    main()
