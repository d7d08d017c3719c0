"""Whether the compiled simulation kernels are cached yet (numba `cache=True`): the first trial after an
install compiles them for tens of seconds, and a user should be told rather than left looking at nothing."""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

# Modules whose @njit(cache=True) kernels every trial runs.
KERNEL_MODULES = ("spinefarm.worker.sim.strings", "spinefarm.worker.control.cpg", "spinefarm.worker.control.law",
                  "spinefarm.worker.engines.couple")


def _cache_dirs(source: Path) -> list[Path]:
    # numba writes beside the module (__pycache__) or, when that is read-only, under NUMBA_CACHE_DIR
    # or the user's cache folder; any of them holding an index means the kernels were compiled before.
    dirs = [source.parent / "__pycache__"]
    if os.environ.get("NUMBA_CACHE_DIR"):
        dirs.append(Path(os.environ["NUMBA_CACHE_DIR"]))
    dirs.append(Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "numba")
    return dirs


def kernels_cached() -> bool:
    """True when every kernel module has a numba cache index somewhere numba looks."""
    for name in KERNEL_MODULES:
        spec = importlib.util.find_spec(name)
        if spec is None or not spec.origin:
            return False
        source = Path(spec.origin)
        pattern = f"{source.stem}.*.nbi"
        if not any(next(d.rglob(pattern), None) is not None for d in _cache_dirs(source) if d.is_dir()):
            return False
    return True
