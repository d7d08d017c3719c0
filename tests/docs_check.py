"""`make docs-check`: run the cheap commands the docs quote and check that the docs say what they print.

    python -m tests.docs_check [--only NAME,...]

Each check runs one documented command (a `spinefarm trial ... --json` of a shipped gait, a few seconds to a
minute on two busy cores), writes its figures into the sentence the doc uses, at the doc's precision, and
looks for that sentence in the doc (whitespace and line breaks aside). Prints JSON, one entry per check, and
exits 1 when a doc no longer says what its command gives."""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# name -> (doc, spinefarm arguments, the doc's sentence with the command's JSON fields in it)
CHECKS: dict[str, tuple[str, tuple[str, ...], str]] = {
    "tetraspine": ("docs/reproducibility.md",
                   ("trial", "tetraspine", "--params", "examples/gaits/tetraspine.json", "--json"),
                   "Tetraspine {distance_m!r} m, {speed_cm_s:.2f} cm/s, COT {cot:.2f}"),
    "ribbed": ("docs/reproducibility.md", ("trial", "ribbed", "--params", "examples/gaits/ribbed.json", "--json"),
               "ribbed {distance_m!r} m, {speed_cm_s:.2f} cm/s, COT {cot:.2f}"),
    "ribbed-every-cpu": ("docs/reproducibility.md",
                         ("trial", "ribbed", "--params", "examples/gaits/ribbed.json", "--json"),
                         "gives `{distance_m!r}` m ({speed_cm_s:.2f} cm/s, COT {cot:.2f})"),
    "efficient-tetraspine": ("docs/results.md",
                             ("trial", "tetraspine", "--params", "examples/gaits/efficient/tetraspine.json", "--json"),
                             "examples/gaits/efficient/tetraspine.json --json`): {speed_cm_s:.2f} cm/s at "
                             "COT {cot:.2f}"),
    "efficient-ribbed": ("docs/results.md",
                         ("trial", "ribbed", "--params", "examples/gaits/efficient/ribbed.json", "--json"),
                         "examples/gaits/efficient/ribbed.json --json`): {speed_cm_s:.2f} cm/s at COT {cot:.2f}"),
}


def _flat(text: str) -> str:
    return re.sub(r"\s+", " ", text)


def run_check(name: str, cache: dict[tuple[str, ...], dict]) -> dict:
    """One check's outcome: the doc, the command, the sentence it should hold, whether it does."""
    doc, args, sentence = CHECKS[name]
    if args not in cache:
        out = subprocess.run([sys.executable, "-m", "spinefarm", *args], cwd=ROOT, capture_output=True, text=True,
                             timeout=900)
        if out.returncode != 0:
            return {"check": name, "doc": doc, "command": "spinefarm " + " ".join(args), "ok": False,
                    "error": out.stderr.strip().splitlines()[-1:]}
        cache[args] = json.loads(out.stdout)
    expected = sentence.format(**cache[args])
    found = _flat(expected) in _flat((ROOT / doc).read_text())
    return {"check": name, "doc": doc, "command": "spinefarm " + " ".join(args), "expected": expected, "ok": found}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default=",".join(CHECKS), help="comma-separated: " + ", ".join(CHECKS))
    names = [n for n in ap.parse_args(argv).only.split(",") if n]
    unknown = [n for n in names if n not in CHECKS]
    if unknown:
        ap.error(f"--only: unknown {', '.join(unknown)}; expected some of {', '.join(CHECKS)}")
    cache: dict[tuple[str, ...], dict] = {}
    results = [run_check(n, cache) for n in names]
    print(json.dumps({"checks": results, "ok": all(r["ok"] for r in results)}, indent=1))
    return 0 if all(r["ok"] for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
