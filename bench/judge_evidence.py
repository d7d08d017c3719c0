"""Which engine judges: the one that moves closer to recorded motion (spinefarm.worker.tools.judge_evidence).

Per spine (the *-ntrt2026 built-ins, whose model is NTRT's current code, which made the recordings): NTRT's
published run and the random draws it ran to the end (../shared/ntrt-recordings, each cut to its first --span
seconds, windows of --window s every --stride s, as bench/fit.py --ntrt), each engine at the judge's 0.25 ms
step with the model's own constants; the window error per recording and engine, the medians, and the engine
the evidence names. Prints {"spines": {SPINE: {"window_error_cm", "median_cm", "closer", "judge", "why",
"wall_s"}}, "command"}.

    python bench/judge_evidence.py [--spines tetraspine-ntrt2026 ...] [--span 10] [--stride 1] [--window 0.2]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from fit import NTRT_FOLDERS, ntrt_recordings  # bench/fit.py: the same recordings, cut alike


def main() -> None:
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.worker.tools.judge_evidence import judge_evidence

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spines", nargs="+", default=sorted(NTRT_FOLDERS), help="*-ntrt2026 built-ins")
    ap.add_argument("--recordings", default="/work/shared/ntrt-recordings", help="NTRT's recordings folder")
    ap.add_argument("--span", type=float, default=10.0, help="seconds of each recording (default 10)")
    ap.add_argument("--stride", type=float, default=1.0, help="a window every S s (default 1)")
    ap.add_argument("--window", type=float, default=0.2, help="window length in s (default 0.2)")
    args = ap.parse_args()
    unknown = sorted(set(args.spines) - set(NTRT_FOLDERS))
    if unknown:
        sys.exit(f"error: no NTRT recordings for {unknown[0]!r} (expected one of {', '.join(sorted(NTRT_FOLDERS))})")
    out: dict = {"spines": {}, "command": "python bench/judge_evidence.py " + " ".join(sys.argv[1:])}
    for spine in args.spines:
        t0 = time.time()
        recs = ntrt_recordings(Path(args.recordings) / NTRT_FOLDERS[spine], args.window, args.stride, args.span)
        out["spines"][spine] = {**judge_evidence(load_morphology(spine), recs), "wall_s": round(time.time() - t0, 1)}
        print(f"{spine}: {out['spines'][spine]['why']}", file=sys.stderr, flush=True)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
