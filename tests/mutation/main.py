"""Run mutmut over the modules that decide and print JSON: killed, survived, timed out, per module.

    python -m tests.mutation.main [--modules robust-scoring,runlock] [--workdir .mutation] [--survivors FILE]

mutmut changes the source in place, so it works on a copy of the tracked files in WORKDIR/tree (an interrupted
run never leaves a mutant in the checkout). Its cache (WORKDIR/tree/.mutmut-cache) is kept: a killed mutant
stays killed, so a second run (after adding tests) tests only the survivors and the mutants of changed lines.
Mutations of strings (messages) and decorators are left out: they rarely decide and would double the count."""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tests.mutation.targets import FUNCTIONS, NO_JIT, TARGETS, TEST_TIME_BASE_S

ROOT = Path(__file__).resolve().parents[2]
STATUSES = {"ok_killed": "killed", "bad_survived": "survived", "bad_timeout": "timed_out",
            "ok_suspicious": "suspicious", "skipped": "skipped", "untested": "untested"}


def copy_tree(dest: Path) -> None:
    """The tracked files as they are in the work tree (edits included), over the last copy; the copy is a
    checkout of its own (the environment record's commit is read from the checkout the code runs in)."""
    names = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, check=True, capture_output=True).stdout
    for name in names.decode().split("\0"):
        src = ROOT / name
        if name and src.is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / name)
    if not (dest / ".git").exists():
        git = ["git", "-C", str(dest), "-c", "user.name=mutation", "-c", "user.email=mutation@localhost"]
        for cmd in (["init", "-q"], ["add", "-A"], ["commit", "-qm", "the code under mutation"]):
            subprocess.run(git + cmd, check=True, capture_output=True)


def mutmut_run(tree: Path, cmd: list[str]) -> bool:
    """Run one `mutmut run`; False when it failed to find a mutant in its cache (mutmut 2.5.1: `Mutant.line is
    required`), after which it waits for its dead checking process for ever: then it is ended."""
    env = dict(os.environ, PYTHONPATH=str(tree), SPINEFARM_MUTATION="1")
    with tempfile.TemporaryFile() as log:
        proc = subprocess.Popen(cmd, cwd=tree, env=env, stdout=log, stderr=subprocess.STDOUT)
        while proc.poll() is None:
            time.sleep(1.0)
            log.seek(0)
            if b"Mutant.line is required" in log.read():
                proc.kill()
                proc.wait()
                return False
        log.seek(0)
        sys.stderr.buffer.write(log.read()[-2000:])
    return True


def runner(tests: tuple[str, ...], no_jit: tuple[str, ...] = ()) -> str:
    """The test command of one mutant. mutmut 2 counts only exit code 1 as killed: a mutant that breaks an
    import (pytest's exit code 2, a collection error) would count as survived, so pytest_exit makes every
    failure 1; the no_jit files run first with numba's compiler off (tests/mutation/pytest_exit.py)."""
    opts = ["-x", "-q", "-p", "no:randomly", "-p", "no:cacheprovider"]
    first = ["--no-jit", *opts, *no_jit, "--then"] if no_jit else []
    return " ".join([sys.executable, "-m", "tests.mutation.pytest_exit", *first, *opts, *tests])


def run_module(tree: Path, module: str, tests: tuple[str, ...], functions: tuple[str, ...] = (),
               no_jit: tuple[str, ...] = (), time_base_s: float = 20.0) -> None:
    """mutmut over the module, then one by one the mutants it left untested or did not re-test: those after a
    mutant it could not look up (that one stays untested), and those on a line whose text repeats an earlier
    line of the module (mutmut 2.5.1 looks a cached status up by the line's text, so after an interrupted run
    or a change of the tests such a mutant takes the earlier line's status and is never queued)."""
    args = ["--paths-to-mutate", module, "--runner", runner(tests, no_jit), "--tests-dir", "tests",
            "--disable-mutation-types", "string,fstring,decorator", "--test-time-base", str(time_base_s),
            "--simple-output", "--no-progress", "--CI"]
    # restricted to some functions: mutmut started through tests.mutation.lines, which hands it their lines
    tool = ["tests.mutation.lines", module, ",".join(functions), "--"] if functions else ["mutmut"]
    # the module as copied when the run began: an edit of the checkout meanwhile (a mutant applied there by
    # hand) must not become the code under mutation
    original = (tree / module).read_bytes()
    mutmut_run(tree, [sys.executable, "-m", *tool, "run", *args])
    for mutant_id in untested(tree, module):
        restore(tree, module, original)
        mutmut_run(tree, [sys.executable, "-m", "mutmut", "run", str(mutant_id), *args])
    restore(tree, module, original)


def restore(tree: Path, module: str, original: bytes) -> None:
    """The module as it was copied, over a mutant an ended mutmut left in the copy."""
    (tree / module).write_bytes(original)
    (tree / f"{module}.bak").unlink(missing_ok=True)


def untested(tree: Path, module: str) -> list[int]:
    """Mutants not run, and survivors last run against other tests than the current ones (mutmut skipped
    them: on a line whose text repeats an earlier line, it read that line's status)."""
    db = sqlite3.connect(tree / ".mutmut-cache")
    rows = db.execute("SELECT m.id FROM Mutant m JOIN Line l ON m.line = l.id JOIN SourceFile f "
                      "ON l.sourcefile = f.id WHERE f.filename = ? AND (m.status = 'untested' OR (m.status IN "
                      "('bad_survived', 'bad_timeout') AND m.tested_against_hash IS NOT (SELECT value FROM "
                      "MiscData WHERE key = 'hash_of_tests')))", (module,)).fetchall()
    db.close()
    return [i for (i,) in rows]


def end_leftovers(tree: Path) -> int:
    """Processes still working in the copy (a timed-out mutant's searches and workers: mutmut kills only the
    pytest it started): ended, as only this run starts processes there. How many."""
    ended = 0
    for proc in Path("/proc").iterdir():
        try:
            if proc.name.isdigit() and Path(os.readlink(proc / "cwd")).is_relative_to(tree.resolve()):
                os.kill(int(proc.name), signal.SIGKILL)
                ended += 1
        except OSError:
            continue
    return ended


def counts(tree: Path, module: str) -> tuple[dict[str, int], list[int]]:
    """Mutants of one module by outcome, and the ids of those that lived (survived or timed out)."""
    db = sqlite3.connect(tree / ".mutmut-cache")
    rows = db.execute("SELECT m.id, m.status FROM Mutant m JOIN Line l ON m.line = l.id "
                      "JOIN SourceFile f ON l.sourcefile = f.id WHERE f.filename = ?", (module,)).fetchall()
    db.close()
    out = dict.fromkeys(STATUSES.values(), 0)
    for _, status in rows:
        out[STATUSES[status]] += 1
    tested = out["killed"] + out["survived"] + out["timed_out"] + out["suspicious"]
    out["killed_pct"] = round(100.0 * (out["killed"] + out["suspicious"]) / tested, 1) if tested else None
    return out, [i for i, s in rows if s in ("bad_survived", "bad_timeout")]


def diff(tree: Path, mutant_id: int) -> str:
    res = subprocess.run([sys.executable, "-m", "mutmut", "show", str(mutant_id)], cwd=tree,
                         capture_output=True, text=True)
    return res.stdout


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--modules", default=",".join(TARGETS), help="comma-separated names: " + ", ".join(TARGETS))
    ap.add_argument("--workdir", type=Path, default=ROOT / ".mutation")
    ap.add_argument("--survivors", type=Path, help="write each survivor's diff here (default WORKDIR/survivors.txt)")
    ap.add_argument("--report-only", action="store_true", help="read the cache, run nothing")
    args = ap.parse_args(argv)
    names = [n for n in args.modules.split(",") if n]
    unknown = [n for n in names if n not in TARGETS]
    if unknown:
        ap.error(f"--modules: unknown {', '.join(unknown)}; expected some of {', '.join(TARGETS)}")
    tree = args.workdir / "tree"
    tree.mkdir(parents=True, exist_ok=True)
    copy_tree(tree)
    report: dict[str, dict] = {}
    lived: list[str] = []
    for name in names:
        module, tests = TARGETS[name]
        started = time.monotonic()
        if not args.report_only:
            run_module(tree, module, tests, FUNCTIONS.get(name, ()), NO_JIT.get(name, ()),
                       TEST_TIME_BASE_S.get(name, 20.0))
            end_leftovers(tree)
        report[name], ids = counts(tree, module)
        report[name].update(module=module, tests=list(tests), seconds=round(time.monotonic() - started))
        if name in FUNCTIONS:
            report[name]["functions"] = list(FUNCTIONS[name])
        if name in NO_JIT:
            report[name]["tests_without_jit_first"] = list(NO_JIT[name])
        lived += [f"## {name} mutant {i}\n{diff(tree, i)}" for i in ids]
    total = {k: sum(r[k] for r in report.values()) for k in STATUSES.values()}
    tested = total["killed"] + total["survived"] + total["timed_out"] + total["suspicious"]
    total["killed_pct"] = round(100.0 * (total["killed"] + total["suspicious"]) / tested, 1) if tested else None
    (args.survivors or args.workdir / "survivors.txt").write_text("\n".join(lived))
    print(json.dumps({"tool": "mutmut 2.5.1", "modules": report, "total": total}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
