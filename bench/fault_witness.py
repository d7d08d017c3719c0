"""The witness: a worker that speaks the real protocol and logs every result the coordinator acknowledged as
stored, and the processes around it (a coordinator, witnesses, the acknowledgement logs, the file checked
against them). bench/faults.py and its tests use it.

A witness started with the fault "drop-grants" asks for work and drops every grant it gets, as a worker whose grants
never reach it (a lost reply, a run config it cannot fetch) does: it never runs a trial.

usage (spawned by witness()): python bench/fault_witness.py ENDPOINT RUN_ID WORKER_ID LOG_PATH [drop-grants]
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from spinefarm.protocol import keys  # noqa: E402
from spinefarm.storage.hdf5_reader import read_run  # noqa: E402


def witness_worker(endpoint: str, run_id: str, worker_id: str, log_path: str, fault: str = "") -> int:
    """The worker protocol (pull, run, carry results with the next request) with an acknowledgement log."""
    import zenoh

    from spinefarm.coordinator.service import zenoh_config
    from spinefarm.protocol.code_digest import code_digest
    from spinefarm.protocol.envelope import decode_message, encode_message
    from spinefarm.protocol.run import RunConfig
    from spinefarm.protocol.submissions import SubmittedResult
    from spinefarm.protocol.work import WorkGrant, WorkRequest
    from spinefarm.worker.service.zenoh_worker import build_evaluator

    session = None
    while session is None:
        try:
            session = zenoh.open(zenoh_config("client", connect=[endpoint]))
        except zenoh.ZError:
            time.sleep(0.1)
    evaluators: dict[str, object] = {}
    pending: dict[int, SubmittedResult] = {}
    with open(log_path, "a") as log:
        while True:
            req = encode_message(WorkRequest(worker_id, 4, tuple(pending.values()), code_digest=code_digest()))
            grants = [decode_message(r.ok.payload.to_bytes(), WorkGrant)
                      for r in session.get(keys.work(run_id), payload=req, timeout=5.0) if r.ok]
            if not grants:
                time.sleep(0.1)
                continue
            g = grants[0]
            for tid, verdict in g.verdicts:
                if tid in pending:
                    if verdict.value == "stored":
                        log.write(json.dumps([tid, pending[tid].result.distance_m]) + "\n")
                        log.flush()
                    del pending[tid]
            if g.run_done:
                session.close()
                return 0
            if fault == "drop-grants":
                time.sleep(0.2)   # a worker's back-off before it asks again
                continue
            if g.config_hash not in evaluators:
                cfgs = [decode_message(r.ok.payload.to_bytes(), RunConfig)
                        for r in session.get(keys.config(run_id, g.config_hash), timeout=5.0) if r.ok]
                if not cfgs:
                    continue
                evaluators[g.config_hash] = build_evaluator(cfgs[0])
            for a in g.assignments:
                r = evaluators[g.config_hash](a)
                pending[a.trial_id] = SubmittedResult(a.lease_id, replace(r, trial_id=a.trial_id, worker_id=worker_id),
                                                      coordinator=g.coordinator)


def spawn(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, *args], cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True)


def coordinator(ep: str, out: Path, *args: str) -> subprocess.Popen:
    tail = ("--resume", str(out)) if not args else (*args, "--out", str(out))
    return spawn("-m", "spinefarm", "coordinator", *tail, "--listen", ep, "--api-port", "-1", "--quiet")


def witness(ep: str, run_id: str, wid: str, log: Path, fault: str = "") -> subprocess.Popen:
    return spawn(str(Path(__file__).resolve()), ep, run_id, wid, str(log), *((fault,) if fault else ()))


def acked(logs: list[Path]) -> list[tuple[int, float]]:
    out = []
    for p in logs:
        if p.exists():
            out += [tuple(json.loads(ln)) for ln in p.read_text().splitlines() if ln.strip()]
    return out


def wait(pred, timeout_s: float, what: str) -> None:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if pred():
            return
        time.sleep(0.05)
    raise TimeoutError(what)


def check_file(out: Path, budget: int, acks: list[tuple[int, float]]) -> dict:
    import numpy as np

    from spinefarm.protocol.errors import StorageError

    try:
        _, cols = read_run(out)
    except StorageError as exc:  # a file that cannot be read has lost everything acknowledged
        ids = [t for t, _ in acks]
        return {"rows": 0, "complete": 0, "budget": budget, "acknowledged": len(ids), "lost": len(ids),
                "duplicated": len(ids) - len(set(ids)), "unreadable": str(exc)[:200]}
    stored = {int(i): float(cols["distance_m"][i]) for i in np.flatnonzero(cols["status"] == b"complete")}
    ids = [t for t, _ in acks]
    return {"rows": len(cols["trial_id"]), "complete": len(stored), "budget": budget,
            "acknowledged": len(ids),
            "lost": sum(1 for t, d in acks if stored.get(t) != d),
            "duplicated": len(ids) - len(set(ids))}


if __name__ == "__main__":
    sys.exit(witness_worker(*sys.argv[1:6]))
