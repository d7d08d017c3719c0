"""Time to a good gait: how long a search with the default settings takes until its first judged best reaches
the paper's speed, per spine and seed, and the best judged within the budget.

    python bench/time_to_quality.py --spines all --seeds 3 [--budget-s 1200] [--workers 2] [--keep DIR]
                                    [--search-arg=--duration --search-arg=10 ...]

Each (spine, seed) runs `spinefarm search SPINE --workers W --seed S` (everything else at its default: engine
`auto`, its calibration included in the time, the judge, the ladder) as a real process with its HTTP API,
polls `GET /runs/{run_id}/best` every --poll-s seconds, and stops it with Ctrl-C (SIGINT: everything stored)
after --budget-s seconds of wall time (the issue's 20 minutes by default). A best counts once the judge
measured it ("judged" in another engine, or "holds" at a finer step): its judged speed is the judge's distance
over the trial's simulated time. The wall and CPU seconds of a best are those of the poll that first saw it
(to within --poll-s); CPU seconds are the search's whole process tree (coordinator and workers, from /proc).

Prints one JSON object (last line): {"spines": {SPINE: {"paper_speed_cm_s", "wall_s_to_paper_speed": [per seed,
null if never], "cpu_s_to_paper_speed": [...], "median_wall_s": (null unless most seeds got there),
"best_judged_cm_s": median over seeds, "best_judged_cm_s_all": [...], "judged": [per seed: [[wall s, cm/s]...]]}},
"budget_s", "workers", "search_args"}.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

# the paper's speeds (Table 2; bench/samplers.py names the same figures)
PAPER_SPEED_CM_S = {"tetraspine": 9.46, "tetrahedral-complex": 6.13, "octahedral-complex": 4.6, "ribbed": 5.37}
JUDGED = ("judged", "holds")
CLK_TCK = os.sysconf("SC_CLK_TCK")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def tree_cpu_s(root_pid: int) -> float:
    """CPU seconds (user + system) of root_pid and every live descendant, with their waited-for children."""
    parents: dict[int, int] = {}
    stats: dict[int, list[str]] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            text = Path(f"/proc/{entry}/stat").read_text()
        except OSError:
            continue
        fields = text[text.rindex(")") + 2:].split()  # after the command name, which may hold spaces
        parents[int(entry)] = int(fields[1])
        stats[int(entry)] = fields
    tree, frontier = {root_pid}, [root_pid]
    while frontier:
        pid = frontier.pop()
        for child, parent in parents.items():
            if parent == pid and child not in tree:
                tree.add(child)
                frontier.append(child)
    ticks = sum(sum(int(stats[p][k]) for k in (11, 12, 13, 14)) for p in tree if p in stats)
    return ticks / CLK_TCK


def judged_speeds(port: int, run_id: str) -> dict[int, float]:
    """Trial id -> judged speed (cm/s) of every judged best the API lists now."""
    url = f"http://127.0.0.1:{port}/runs/{run_id}/best?k=50"
    with urllib.request.urlopen(url, timeout=10) as resp:
        rows = json.load(resp)
    out = {}
    for row in rows:
        v = row["verification"]
        judge_m = v.get("judge_distance_m") if v["verdict"] == "judged" else v.get("fine_step_distance_m")
        sim_s = row["scores"].get("sim_time_s")
        if v["verdict"] in JUDGED and judge_m is not None and sim_s:
            out[int(row["trial_id"])] = judge_m * 100.0 / sim_s
    return out


def run_one(spine: str, seed: int, args: argparse.Namespace, out_dir: Path) -> dict:
    """One search for --budget-s seconds; the judged bests as the polls first saw them."""
    port, run_id = free_port(), f"ttq-{spine}-{seed}"
    cmd = [sys.executable, "-m", "spinefarm", "search", spine, "--workers", str(args.workers), "--seed", str(seed),
           "--trials", str(args.trials), "--out", str(out_dir / f"{run_id}.h5"), "--overwrite", "--run-id", run_id,
           "--api-port", str(port), "--quiet", *args.search_arg]
    log = (out_dir / f"{run_id}.log").open("w")
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, start_new_session=True, cwd=ROOT)
    seen: dict[int, tuple[float, float, float]] = {}  # trial -> (wall s, CPU s, judged cm/s)
    while proc.poll() is None and time.perf_counter() - t0 < args.budget_s:
        time.sleep(args.poll_s)
        try:
            speeds = judged_speeds(port, run_id)
        except (urllib.error.URLError, OSError, ValueError, KeyError):  # not serving yet (calibrating, starting)
            continue
        wall, cpu = time.perf_counter() - t0, tree_cpu_s(proc.pid)
        for trial, speed in speeds.items():
            seen.setdefault(trial, (wall, cpu, speed))
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGINT)  # the search stores everything and stops
        try:
            proc.wait(timeout=180)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    log.close()
    paper = PAPER_SPEED_CM_S.get(spine, math.inf)
    order = sorted(seen.values())
    first = next(((w, c) for w, c, s in order if s >= paper), (None, None))
    best = max((s for _, _, s in order), default=None)
    print(f"{spine} seed {seed}: paper speed after {first[0]} s wall, best judged {best} cm/s", file=sys.stderr)
    return {"wall_s": first[0], "cpu_s": first[1], "best_cm_s": best, "exit_code": proc.returncode,
            "judged": [[round(w, 1), round(s, 3)] for w, _, s in order]}


def summarise(spine: str, runs: list[dict]) -> dict:
    walls = [r["wall_s"] for r in runs]
    reached = sorted(w for w in walls if w is not None)
    # the median of the seeds, a seed that never got there counting as longer than any that did
    median = reached[len(walls) // 2] if len(reached) > len(walls) // 2 else None
    bests = [r["best_cm_s"] for r in runs]
    known = [b for b in bests if b is not None]
    return {"paper_speed_cm_s": PAPER_SPEED_CM_S.get(spine), "wall_s_to_paper_speed": walls,
            "cpu_s_to_paper_speed": [r["cpu_s"] for r in runs], "median_wall_s": median,
            "best_judged_cm_s": float(np.median(known)) if known else None, "best_judged_cm_s_all": bests,
            "judged": [r["judged"] for r in runs], "exit_codes": [r["exit_code"] for r in runs]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spines", default="all", help="all (the paper's four) or names separated by commas")
    ap.add_argument("--seeds", type=int, default=3, help="searches per spine, seeds 1..N (default 3)")
    ap.add_argument("--budget-s", type=float, default=1200.0, help="wall seconds per search (default 1200)")
    ap.add_argument("--workers", type=int, default=2, help="worker processes per search (default 2)")
    ap.add_argument("--trials", type=int, default=1_000_000, help="trial budget (default: more than fits)")
    ap.add_argument("--poll-s", type=float, default=5.0, help="seconds between the API's polls (default 5)")
    ap.add_argument("--keep", type=Path, default=None, help="keep the run files and logs here")
    ap.add_argument("--search-arg", action="append", default=[],
                    help="one more argument for every search (repeatable; e.g. --search-arg=--duration)")
    args = ap.parse_args()
    names = list(PAPER_SPEED_CM_S) if args.spines == "all" else args.spines.split(",")
    unknown = [n for n in names if n not in PAPER_SPEED_CM_S]
    if unknown:
        sys.exit(f"time_to_quality: --spines: no paper speed for {unknown}; expected some of {list(PAPER_SPEED_CM_S)}")
    if args.seeds < 1 or args.budget_s <= 0:
        sys.exit(f"time_to_quality: --seeds {args.seeds} and --budget-s {args.budget_s}: expected >= 1 and > 0")
    with tempfile.TemporaryDirectory() as tmp:
        out_dir = args.keep or Path(tmp)
        out_dir.mkdir(parents=True, exist_ok=True)
        spines = {n: summarise(n, [run_one(n, s, args, out_dir) for s in range(1, args.seeds + 1)]) for n in names}
    print(json.dumps({"spines": spines, "budget_s": args.budget_s, "workers": args.workers,
                      "search_args": args.search_arg}))


if __name__ == "__main__":
    main()
