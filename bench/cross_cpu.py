"""The same trial on other x86-64 CPUs, emulated: do its bits match this machine's?

    python bench/cross_cpu.py [--cpus Haswell,Nehalem] [--duration 0.2] [--engines bullet,mujoco]

Runs a shipped gait natively, then under `qemu-x86_64 -cpu MODEL` (qemu-user) with the same interpreter and
packages, and prints JSON: per CPU model and engine, the trial's fingerprint (distance, work, a hash of the
robot's path and final poses) and whether it equals the native one bit for bit. An emulated trial runs
~20-50x slower, so keep --duration at a fraction of a second. numba compiles for the CPU it detects; its
kernels for an emulated model are compiled natively first, for exactly the CPU name and features that model
reports (numba's cache is keyed by them), because compiling under emulation takes minutes. MuJoCo's wheel
needs AVX: CPU models without it (Nehalem) run the Bullet tier only. `libm_differences` counts the
`libm_calls` seeded sin, cos and exp results (glibc's, which the CPG calls) that differ between this CPU and each model.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
GAIT = ROOT / "examples" / "gaits" / "tetraspine.json"
AVX_FREE = {"Nehalem", "Westmere", "Penryn", "Conroe", "qemu64"}
_QEMU_QUIET = ("warning: TCG doesn't support",)


def fingerprint(gait: Path, engine: str, duration_s: float, seed: int = 1) -> dict:
    """One trial of a gait file in this process: its score's bits and hashes of its path and final poses."""
    import numpy as np

    from spinefarm.robot.trial_config import TrialConfig
    from spinefarm.worker.trial.simulation import simulate

    spec = json.loads(gait.read_text())
    t0 = time.perf_counter()
    out = simulate(spec["morphology"], spec["params"], TrialConfig(duration_s=duration_s, engine=engine), seed,
                   controller=spec.get("controller"))
    r = out.result
    path = np.ascontiguousarray(out.com_path_cm, dtype=float)
    return {"distance_m": r.distance_m, "distance_bits": r.distance_m.hex(), "work_bits": r.work_j.hex(),
            "path_sha": hashlib.sha256(path.tobytes()).hexdigest()[:16], "status": r.status.value,
            "wall_s": round(time.perf_counter() - t0, 2)}


def _child_cmd(engine: str, duration_s: float) -> list[str]:
    return [sys.executable, str(Path(__file__).resolve()), "--child", "--engines", engine,
            "--duration", repr(duration_s)]


def _last_json(stdout: str) -> dict:
    lines = [ln for ln in stdout.splitlines() if ln.startswith("{")]
    if not lines:
        raise RuntimeError(f"no JSON from the child: {stdout[-500:]!r}")
    return json.loads(lines[-1])


def emulated_target(cpu: str) -> tuple[str, str]:
    """(LLVM CPU name, feature string) that numba detects on `cpu` under qemu-user."""
    code = "import llvmlite.binding as ll; print(ll.get_host_cpu_name()); print(ll.get_host_cpu_features().flatten())"
    out = subprocess.run(["qemu-x86_64", "-cpu", cpu, sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=300)
    name, features = out.stdout.split()[-2:]
    return name, features


def run_emulated(cpu: str, engine: str, duration_s: float, cache_dir: Path) -> dict:
    """The fingerprint of a trial under `qemu-x86_64 -cpu cpu`, numba's kernels compiled natively first."""
    name, features = emulated_target(cpu)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache_dir)}
    warm = {**env, "NUMBA_CPU_NAME": name, "NUMBA_CPU_FEATURES": features}
    subprocess.run(_child_cmd(engine, 0.01), env=warm, capture_output=True, text=True, check=True, timeout=600)
    out = subprocess.run(["qemu-x86_64", "-cpu", cpu, *_child_cmd(engine, duration_s)], env=env,
                         capture_output=True, text=True, timeout=1800)
    if out.returncode != 0:
        err = "\n".join(ln for ln in out.stderr.splitlines() if not ln.startswith("qemu-x86_64: " + _QEMU_QUIET[0]))
        raise RuntimeError(f"the trial under qemu -cpu {cpu} failed ({out.returncode}): {err[-800:]}")
    return {**_last_json(out.stdout), "llvm_cpu": name}


_LIBM_PROBE = """
import math, random, struct, sys
rng = random.Random(1)
xs = [rng.uniform(-60.0, 60.0) for _ in range(int(sys.argv[1]))]
sys.stdout.buffer.write(b"".join(struct.pack("d", f(x)) for f in (math.sin, math.cos, math.exp) for x in xs))
"""


def libm_differences(cpu: str, n: int = 200_000) -> dict[str, int]:
    """How many of n seeded sin, cos and exp results (glibc's libm, which numba's kernels call too) differ in
    any bit between this CPU and `cpu` emulated: glibc picks FMA variants of them on CPUs that have FMA."""
    import numpy as np

    def values(prefix: list[str]) -> np.ndarray:
        out = subprocess.run([*prefix, sys.executable, "-c", _LIBM_PROBE, str(n)], capture_output=True, check=True,
                             timeout=1800)
        return np.frombuffer(out.stdout, dtype=float).reshape(3, n)

    native, emulated = values([]), values(["qemu-x86_64", "-cpu", cpu])
    return {name: int((a != b).sum()) for name, a, b in zip(("sin", "cos", "exp"), native, emulated, strict=True)}


def compare(cpus: list[str], engines: list[str], duration_s: float, libm_n: int = 200_000) -> dict:
    """Native and emulated fingerprints side by side, with `same_bits` per CPU model and engine."""
    if shutil.which("qemu-x86_64") is None:
        raise SystemExit("cross_cpu needs qemu-user: run 'apt-get install qemu-user' (or sh .ci/ensure-qemu-user)")
    report: dict = {"duration_s": duration_s, "gait": GAIT.name, "engines": {},
                    "libm_calls": libm_n, "libm_differences": {cpu: libm_differences(cpu, libm_n) for cpu in cpus}}
    with tempfile.TemporaryDirectory(prefix="spinefarm-cross-cpu-") as tmp:
        for engine in engines:
            native = _last_json(subprocess.run(_child_cmd(engine, duration_s), capture_output=True, text=True,
                                               check=True, timeout=600).stdout)
            rows = {"native": native}
            for cpu in cpus:
                if engine == "mujoco" and cpu in AVX_FREE:
                    rows[cpu] = {"skipped": "MuJoCo's wheel needs AVX"}
                    continue
                emu = run_emulated(cpu, engine, duration_s, Path(tmp) / cpu)
                emu["same_bits"] = all(emu[k] == native[k] for k in ("distance_bits", "work_bits", "path_sha"))
                rows[cpu] = emu
            report["engines"][engine] = rows
    return report


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cpus", default="Haswell,Nehalem", help="qemu CPU models (qemu-x86_64 -cpu help)")
    ap.add_argument("--engines", default="bullet,mujoco")
    ap.add_argument("--duration", type=float, default=0.2, help="simulated seconds per trial")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    engines = [e for e in args.engines.split(",") if e]
    if args.child:
        print(json.dumps(fingerprint(GAIT, engines[0], args.duration)))
        return
    print(json.dumps(compare([c for c in args.cpus.split(",") if c], engines, args.duration), indent=1))


if __name__ == "__main__":
    main()
