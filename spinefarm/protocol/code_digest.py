"""The digest of the code that simulates: what makes two workers' results of one trial the same bits.

A worker announces it with every work request and the coordinator refuses a worker whose digest is not its
own (an old install gives distances a few tenths of a percent off, unmarked). It hashes the sources of the
modules a trial runs through (robot model, engines, control law, string kernel, the trial loop and its
scoring), read as files, so the coordinator computes it without importing a simulator.
"""

from __future__ import annotations

import functools
import hashlib
import re
from pathlib import Path

from spinefarm.protocol.errors import MessageError

_PACKAGE = Path(__file__).resolve().parent.parent
# whole folders, then single modules, relative to the package (the "Trial" part of the architecture)
SIMULATING_DIRS = ("robot", "worker/engines", "worker/control", "worker/sim")
SIMULATING_MODULES = ("worker/trial/simulation.py", "worker/trial/loop.py", "worker/trial/batch.py",
                      "worker/trial/scoring.py", "worker/trial/episode.py", "worker/trial/setup.py",
                      "worker/trial/settled.py", "worker/trial/robust.py", "worker/service/assignment.py",
                      "worker/service/evaluators.py", "protocol/run.py", "protocol/params.py")
_DIGEST = re.compile(r"^[0-9a-f]{64}$")


def simulating_sources(package: Path = _PACKAGE) -> list[Path]:
    """The source files hashed, in a fixed order (relative paths sorted)."""
    files = [p for d in SIMULATING_DIRS for p in (package / d).rglob("*.py")]
    files += [package / m for m in SIMULATING_MODULES if (package / m).is_file()]
    return sorted(set(files), key=lambda p: p.relative_to(package).as_posix())


def digest_of(package: Path) -> str:
    """sha256 over each simulating source's relative path and bytes (a renamed module changes it too)."""
    h = hashlib.sha256()
    for path in simulating_sources(package):
        rel = path.relative_to(package).as_posix().encode()
        data = path.read_bytes()
        h.update(len(rel).to_bytes(4, "big") + rel + len(data).to_bytes(8, "big") + data)
    return h.hexdigest()


@functools.cache
def code_digest() -> str:
    """This install's digest (read once per process)."""
    return digest_of(_PACKAGE)


def check_digest(value: object, what: str) -> str:
    """A digest as a peer sends it: 64 lowercase hex digits."""
    if not isinstance(value, str) or not _DIGEST.match(value):
        raise MessageError(f"{what} is not a code digest", received=str(value)[:70],
                           expected="64 lowercase hex digits (sha256)")
    return value
