"""What a result was computed with: Python, package versions, CPU, BLAS kernel, spinefarm's version and commit.

`environment_record()` is stored with every run file (RunMeta.environment) and printed by
`spinefarm trial --json`; `differences(recorded)` says, one line each, what differs here from a recorded one.
Standard library only (numpy's BLAS is looked up only when numpy is already imported), so any service can
record itself.
"""

from __future__ import annotations

import ctypes
import os
import platform
import re
import subprocess
import sys
from functools import lru_cache
from importlib import metadata
from pathlib import Path
from typing import Any

# what a trial's figures depend on: a difference in one of these is named first
MODEL_PACKAGES = ("numpy", "numba", "llvmlite", "pybullet", "mujoco", "pyyaml")
ENV_VARS = ("OPENBLAS_CORETYPE", "OPENBLAS_L2_SIZE", "NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES", "NUMBA_OPT")


def _cpu() -> tuple[str, str]:
    """(model name, flags) from /proc/cpuinfo; platform's guesses elsewhere."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return platform.processor() or platform.machine(), ""
    model = re.search(r"^model name\s*:\s*(.*)$", text, re.M)
    flags = re.search(r"^flags\s*:\s*(.*)$", text, re.M)
    return (model.group(1).strip() if model else platform.machine()), (flags.group(1).strip() if flags else "")


def _blas() -> dict[str, str | None]:
    """numpy's BLAS: library, version, the kernel OpenBLAS picked for this CPU and its threads (None where
    unknown)."""
    out: dict[str, str | int | None] = {"library": None, "version": None, "kernel": None, "threads": None}
    if "numpy" not in sys.modules:
        return out
    try:
        info = sys.modules["numpy"].show_config(mode="dicts")["Build Dependencies"]["blas"]
        out["library"], out["version"] = info.get("name"), info.get("version")
        maps = Path("/proc/self/maps").read_text()
        for lib in sorted(set(re.findall(r"(/\S*openblas\S*\.so\S*)", maps))):
            handle = ctypes.CDLL(lib)
            for name in ("scipy_openblas_get_num_threads64_", "scipy_openblas_get_num_threads",
                         "openblas_get_num_threads"):
                threads = getattr(handle, name, None)
                if threads is not None:
                    out["threads"] = int(threads())
                    break
            for name in ("scipy_openblas_get_corename64_", "scipy_openblas_get_corename", "openblas_get_corename"):
                fn = getattr(handle, name, None)
                if fn is not None:
                    fn.restype = ctypes.c_char_p
                    out["kernel"] = fn().decode()
                    return out
    except (OSError, KeyError, AttributeError, TypeError, ValueError):
        pass
    return out


def _commit() -> str | None:
    """The source checkout's commit (with "+dirty" when tracked files changed), SPINEFARM_COMMIT where there is
    no checkout (an image sets it at build time), else None."""
    root = Path(__file__).resolve().parents[2]
    try:
        head = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                              timeout=10)
        if head.returncode == 0 and (root / ".git").exists():
            dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                                   capture_output=True, text=True, timeout=10).stdout.strip()
            return head.stdout.strip() + ("+dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        pass
    return os.environ.get("SPINEFARM_COMMIT") or None


def _packages() -> dict[str, str]:
    found = {}
    for dist in metadata.distributions():
        name = dist.metadata.get("Name")
        if name:
            found[name.lower().replace("_", "-")] = dist.version
    return dict(sorted(found.items()))


@lru_cache(maxsize=1)
def _static_record() -> dict[str, Any]:
    model, flags = _cpu()
    libc, libc_version = platform.libc_ver()
    packages = _packages()
    return {
        "python": platform.python_version(), "python_implementation": platform.python_implementation(),
        "platform": platform.platform(), "machine": platform.machine(),
        "libc": f"{libc} {libc_version}".strip(), "cpu_model": model, "cpu_flags": flags,
        "spinefarm_version": packages.get("spinefarm", "unknown"), "spinefarm_commit": _commit(),
        "packages": packages,
    }


def environment_record() -> dict[str, Any]:
    """This process's environment as a JSON-able dict (a fresh copy; the BLAS kernel as of now)."""
    rec = _static_record()
    return {**rec, "packages": dict(rec["packages"]), "blas": _blas(),
            "env": {k: os.environ[k] for k in ENV_VARS if k in os.environ}}


def differences(recorded: dict[str, Any] | None, current: dict[str, Any] | None = None) -> list[str]:
    """What differs between a recorded environment and this one (or `current`): one short line each, the
    model path's packages first. A run file without a record gives one line saying so."""
    if not recorded:
        return ["the run file records no environment (written before spinefarm recorded one)"]
    here = current or environment_record()
    lines = []
    for key, label in (("spinefarm_version", "spinefarm"), ("spinefarm_commit", "commit"), ("python", "Python")):
        if recorded.get(key) != here.get(key):
            lines.append(f"{label} {here.get(key)} here, {recorded.get(key)} in the run")
    rp, hp = recorded.get("packages", {}), here.get("packages", {})
    names = [n for n in MODEL_PACKAGES if n in rp or n in hp] + sorted((set(rp) | set(hp)) - set(MODEL_PACKAGES))
    for name in names:
        if name != "spinefarm" and rp.get(name) != hp.get(name):
            lines.append(f"{name} {hp.get(name, 'missing')} here, {rp.get(name, 'missing')} in the run")
    if recorded.get("cpu_model") != here.get("cpu_model"):
        lines.append(f"CPU {here.get('cpu_model')!r} here, {recorded.get('cpu_model')!r} in the run "
                     "(a trial's bits do not depend on it: docs/reproducibility.md)")
    if recorded.get("env", {}) != here.get("env", {}):
        lines.append(f"environment variables {here.get('env', {})} here, {recorded.get('env', {})} in the run")
    return lines


def describe_differences(recorded: dict[str, Any] | None, current: dict[str, Any] | None = None) -> str:
    """One message for a user ("" when nothing differs)."""
    lines = differences(recorded, current)
    if not lines:
        return ""
    return "the environment differs from the run's: " + "; ".join(lines)
