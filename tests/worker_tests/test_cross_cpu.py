"""One commit, the same bits on every x86-64 CPU: a short trial under emulated CPU models (qemu-user) against
this machine's, and no BLAS call, nor numpy's vectorised sine and kin, left in the code a trial runs."""

from __future__ import annotations

import ast
import shutil
from pathlib import Path

import numpy as np
import pytest

from bench.cross_cpu import compare
from spinefarm.robot import fixedmath as fm

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "spinefarm"
# every module a trial's numbers pass through (drawing, the morphology contract and the accuracy sweeps only read
# results and are left out)
MODEL_PATH = [*sorted((PACKAGE / "robot").rglob("*.py")),
              *[PACKAGE / "worker" / f for f in ("trial/simulation.py", "trial/episode.py", "trial/setup.py",
                                              "trial/scoring.py", "tools/verify.py", "tools/replay.py",
                                              "trial/loop.py", "trial/batch.py")],
              *(p for sub in ("engines", "sim", "control") for p in sorted((PACKAGE / "worker" / sub).glob("*.py")))]
BLAS_CALLS = {"dot", "matmul", "einsum", "inner", "vdot", "tensordot", "outer", "kron"}
# LAPACK's eigenvalues give the stable-step estimate; their result is rounded (fixedmath.round_significant)
ALLOWED = {("spinefarm/worker/sim/stability.py", "np.linalg.eigvalsh")}


def _blas_uses(path: Path, rel: str | None = None) -> list[str]:
    rel = rel or path.relative_to(ROOT).as_posix()
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.BinOp | ast.AugAssign) and isinstance(node.op, ast.MatMult):
            found.append(f"{rel}:{node.lineno}: @")
        elif isinstance(node, ast.Attribute):
            owner, name = ast.unparse(node.value), ast.unparse(node)
            blas = (node.attr in BLAS_CALLS and owner != "fm") or owner in ("np.linalg", "numpy.linalg")
            if blas and (rel, name) not in ALLOWED:
                found.append(f"{rel}:{node.lineno}: {name}")
    return found


def test_no_blas_in_the_model_path():
    assert len(MODEL_PATH) > 20
    found = [use for path in MODEL_PATH for use in _blas_uses(path)]
    assert found == [], "BLAS-dispatched calls in the model path (use spinefarm.robot.fixedmath):\n" + "\n".join(found)


def test_the_scan_sees_a_blas_call(tmp_path):
    bad = tmp_path / "probe.py"
    bad.write_text("import numpy as np\n\ndef f(a, b):\n    return a @ b + np.linalg.norm(a) + a.dot(b)\n")
    assert len(_blas_uses(bad, "spinefarm/worker/sim/probe.py")) == 3


# numpy's transcendental ufuncs run its own vectorised code on AVX-512 CPUs (X86_V4) and glibc's elsewhere: the
# last bits differ. Compiled kernels (numba) call glibc's, so only code outside them is held to this.
TRANSCENDENTAL = {"sin", "cos", "tan", "arcsin", "arccos", "arctan", "arctan2", "sinh", "cosh", "tanh", "arcsinh",
                  "arccosh", "arctanh", "exp", "exp2", "expm1", "log", "log2", "log10", "log1p", "power",
                  "float_power", "cbrt", "hypot", "sinc"}


def _compiled(fn: ast.AST) -> bool:
    return any("jit" in ast.unparse(d) for d in getattr(fn, "decorator_list", ()))


def _vectorised_libm_uses(path: Path, rel: str | None = None) -> list[str]:
    rel = rel or path.relative_to(ROOT).as_posix()
    found: list[str] = []

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.FunctionDef) and _compiled(node):
            return
        if isinstance(node, ast.Attribute) and node.attr in TRANSCENDENTAL and ast.unparse(node.value) in (
                "np", "numpy"):
            found.append(f"{rel}:{node.lineno}: {ast.unparse(node)}")
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(ast.parse(path.read_text()))
    return found


def test_no_vectorised_transcendental_in_the_model_path():
    found = [use for path in MODEL_PATH for use in _vectorised_libm_uses(path)]
    assert found == [], "numpy transcendental calls in the model path (use math's, glibc's):\n" + "\n".join(found)


def test_the_scan_sees_a_vectorised_sine_but_not_a_compiled_one(tmp_path):
    probe = tmp_path / "probe.py"
    probe.write_text("import numpy as np\nfrom numba import njit\n\n@njit(cache=True)\ndef k(x):\n"
                     "    return np.sin(x)\n\ndef f(x):\n    return np.arctan2(x, 1.0) + np.exp(x)\n")
    uses = _vectorised_libm_uses(probe, "spinefarm/robot/probe.py")
    assert [u.split(": ")[1] for u in uses] == ["np.arctan2", "np.exp"]


def test_fixedmath_equals_numpy_to_rounding():
    rng = np.random.default_rng(3)
    m, v, p, b = rng.normal(size=(3, 3)), rng.normal(size=3), rng.normal(size=(7, 3)), rng.normal(size=(3, 4))
    assert np.allclose(fm.matvec(m, v), m @ v, rtol=1e-14, atol=1e-14)
    assert np.allclose(fm.matmul(m, b), m @ b, rtol=1e-14, atol=1e-14)
    assert np.allclose(fm.rotate_rows(p, m), p @ m.T, rtol=1e-14, atol=1e-14)
    assert fm.norm(np.array([3.0, 4.0, 12.0])) == 13.0
    assert np.array_equal(fm.norm(np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 2.0]])), [5.0, 2.0])
    assert fm.dot(v, v) == v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
    assert fm.round_significant(0.1234567894999) == 0.123456789


def test_a_trial_has_the_same_bits_on_other_cpus():
    """Both engines under an AVX2+FMA CPU (Haswell, OpenBLAS's Haswell kernels) against this machine (AVX-512,
    SkylakeX kernels): before BLAS left the model path, they already split at 0.2 s. CPUs without FMA are not
    claimed: glibc's sin and cos differ there in the last bit (docs/reproducibility.md)."""
    if shutil.which("qemu-x86_64") is None:
        pytest.skip("qemu-user is not installed: run sh .ci/ensure-qemu-user (make test does) or apt-get install it")
    report = compare(["Haswell"], ["bullet", "mujoco"], duration_s=0.1, libm_n=50_000)
    assert report["libm_differences"]["Haswell"] == {"sin": 0, "cos": 0, "exp": 0}
    for engine, rows in report["engines"].items():
        native = rows["native"]
        assert native["status"] == "complete" and native["distance_m"] > 0.0, (engine, native)
        for cpu, row in rows.items():
            if cpu == "native" or "skipped" in row:
                continue
            assert row["same_bits"], f"{engine} under {cpu}: {row} against native {native}"
    assert "same_bits" in report["engines"]["bullet"]["Haswell"]
    assert "same_bits" in report["engines"]["mujoco"]["Haswell"]
