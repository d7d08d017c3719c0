"""Stable-step estimate of the explicit string network, linearised at the start pose.

Strings are integrated explicitly: their forces are computed from the state at the start of a step
and held while the engine advances it (semi-implicit Euler). For a mode with natural frequency
omega and damping rate gamma that scheme is stable only while omega^2 dt^2 + 2 gamma dt < 4, i.e.
dt < 2/omega without damping and dt < 2/gamma without stiffness. The network's stiffness and
damping matrices are sum_i k_i J_i^T J_i and sum_i b_i J_i^T J_i, where J_i maps the bodies'
twists to string i's length rate; omega^2 and gamma are the largest generalised eigenvalues against
the mass matrix (mass and inertia of every segment).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from spinefarm.robot import fixedmath as fm
from spinefarm.robot.bodies import build_bodies, build_strings
from spinefarm.robot.morphology.model import Morphology


@dataclass(frozen=True)
class StabilityEstimate:
    """omega_max_rad_s: fastest string-network mode; gamma_max_per_s: largest damping rate;
    dt_limit_s: largest step with omega^2 dt^2 + 2 gamma dt < 4 (taking both maxima together,
    which is conservative)."""

    omega_max_rad_s: float
    gamma_max_per_s: float
    dt_spring_limit_s: float
    dt_damping_limit_s: float
    dt_limit_s: float

    def to_dict(self) -> dict[str, float]:
        return {k: float(v) for k, v in self.__dict__.items()}


def _largest_generalised_eig(a: np.ndarray, inv_sqrt_m: np.ndarray) -> float:
    """Largest eigenvalue against the mass matrix, to 9 significant digits: LAPACK's last bits depend on the
    CPU's BLAS kernels, and a step chosen from them would too."""
    sym = inv_sqrt_m[:, None] * a * inv_sqrt_m[None, :]
    return fm.round_significant(max(float(np.linalg.eigvalsh(0.5 * (sym + sym.T)).max()), 0.0))


def estimate_stable_step(morph: Morphology, relocate_anchors: bool = True) -> StabilityEstimate:
    bodies = build_bodies(morph.structure)
    geom = build_strings(morph.structure, bodies, relocate_anchors)
    nb = len(bodies)
    n = len(geom.start_length_cm)
    jac = np.zeros((n, 6 * nb))
    for i in range(n):
        a, b = int(geom.body_a[i]), int(geom.body_b[i])
        pa = bodies[a].com_cm + geom.anchor_a_cm[i]
        pb = bodies[b].com_cm + geom.anchor_b_cm[i]
        u = (pb - pa) / max(fm.norm(pb - pa), 1e-12)
        jac[i, 6 * a:6 * a + 3] -= u
        jac[i, 6 * a + 3:6 * a + 6] -= np.cross(geom.anchor_a_cm[i], u)
        jac[i, 6 * b:6 * b + 3] += u
        jac[i, 6 * b + 3:6 * b + 6] += np.cross(geom.anchor_b_cm[i], u)
    tags = [s.tag for s in morph.structure.strings]
    k = np.array([morph.structure.string_material(t).stiffness_n_per_m for t in tags])
    c = np.array([morph.structure.string_material(t).damping_n_s_per_m for t in tags])
    mass_diag = np.concatenate([np.r_[np.full(3, b.mass_kg), b.inertia_kg_cm2] for b in bodies])
    inv_sqrt_m = 1.0 / np.sqrt(mass_diag)
    omega = math.sqrt(_largest_generalised_eig(fm.matmul(jac.T, k[:, None] * jac), inv_sqrt_m))
    gamma = _largest_generalised_eig(fm.matmul(jac.T, c[:, None] * jac), inv_sqrt_m)
    dt_spring = 2.0 / omega if omega > 0 else math.inf
    dt_damp = 2.0 / gamma if gamma > 0 else math.inf
    # the positive root of omega^2 dt^2 + 2 gamma dt = 4
    dt_limit = (-gamma + math.sqrt(gamma**2 + 4.0 * omega**2)) / omega**2 if omega > 0 else dt_damp
    return StabilityEstimate(omega, gamma, dt_spring, dt_damp, dt_limit)
