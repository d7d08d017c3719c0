"""Small linear algebra in one fixed order of operations, without BLAS or LAPACK.

numpy hands `@`, `np.dot`, `np.matmul` and the norm of a whole vector to OpenBLAS, which picks its kernels by
CPU (SSE, AVX2, AVX-512) and so sums products in a different order, or fused, on different machines. A trial is
chaotic: one last bit of a start pose grows into percents of distance in 30 s. Everything a trial computes
goes through the functions here instead: elementwise multiplies and adds, each one correctly rounded IEEE
arithmetic, summed left to right over the inner index, so the same inputs give the same bits on every x86-64
CPU.
"""

from __future__ import annotations

import numpy as np


def matvec(m: np.ndarray, v: np.ndarray) -> np.ndarray:
    """m @ v for m (r, c) and v (c,): (r,), summed over c in order."""
    m = np.asarray(m, dtype=float)
    v = np.asarray(v, dtype=float)
    out = m[:, 0] * v[0]
    for j in range(1, m.shape[1]):
        out = out + m[:, j] * v[j]
    return out


def matmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a @ b for a (r, k) and b (k, c): (r, c), summed over k in order."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    out = a[:, 0:1] * b[0:1, :]
    for j in range(1, a.shape[1]):
        out = out + a[:, j:j + 1] * b[j:j + 1, :]
    return out


def rotate_rows(points: np.ndarray, m: np.ndarray) -> np.ndarray:
    """points @ m.T for points (n, 3) and a matrix m (3, 3): every row mapped by m, (n, 3)."""
    p = np.asarray(points, dtype=float)
    m = np.asarray(m, dtype=float)
    out = p[:, 0:1] * m[None, :, 0]
    for j in range(1, m.shape[1]):
        out = out + p[:, j:j + 1] * m[None, :, j]
    return out


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray | float:
    """Sum of a * b over the last axis, in order: a float for vectors, an array for stacks of them."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    out = a[..., 0] * b[..., 0]
    for j in range(1, a.shape[-1]):
        out = out + a[..., j] * b[..., j]
    return float(out) if out.ndim == 0 else out


def norm(v: np.ndarray) -> np.ndarray | float:
    """Euclidean length over the last axis: a float for a vector, an array for a stack of them."""
    return np.sqrt(dot(v, v)) if np.ndim(v) > 1 else float(np.sqrt(dot(v, v)))


def round_significant(x: float, digits: int = 9) -> float:
    """x rounded to `digits` significant decimal digits: for figures that only LAPACK can give (eigenvalues),
    whose last bits differ between CPUs; rounded, they agree unless x lies within ~1e-15 of a rounding edge."""
    return float(f"{x:.{digits}g}")
