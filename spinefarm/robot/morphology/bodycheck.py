"""Checks a body passes before any physics runs: no rod passes through a rod of another segment, and every
string's start rest length (start length - pretension / k) is at least its floor. A co-designed search
asks them of every sampled body; `spinefarm check` of a `search:` block asks them along each range."""

from __future__ import annotations

import numpy as np

from spinefarm.robot.fixedmath import norm
from spinefarm.robot.morphology.structure import StructureSpec


def _segment_distances(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """Closest distance between segments p0-p1 and q0-q1, row by row (clamped to both segments)."""
    u, v, w = p1 - p0, q1 - q0, p0 - q0
    a, b, c = (u * u).sum(1), (u * v).sum(1), (v * v).sum(1)
    d, e = (u * w).sum(1), (v * w).sum(1)
    den = a * c - b * b
    parallel = den < 1e-12 * a * c
    s = np.where(parallel, 0.0, np.clip((b * e - c * d) / np.where(parallel, 1.0, den), 0.0, 1.0))
    t = (b * s + e) / c
    t_clamped = np.clip(t, 0.0, 1.0)
    # where t was clamped, s is re-solved for that end and clamped again
    s = np.where(t != t_clamped, np.clip((t_clamped * b - d) / a, 0.0, 1.0), s)
    gap = w + s[:, None] * u - t_clamped[:, None] * v
    return np.sqrt((gap * gap).sum(1))


def crossing_rods(structure: StructureSpec) -> str | None:
    """The first pair of rods on different segments closer than their two radii, said in words; None if none."""
    pts = structure.node_array()
    ends = np.array([[r.a, r.b] for r in structure.rods])
    seg = np.asarray(structure.node_segment)[ends[:, 0]]
    radius = np.array([structure.rod_material(r.tag).radius_cm for r in structure.rods])
    i, j = np.triu_indices(len(ends), k=1)
    keep = seg[i] != seg[j]
    i, j = i[keep], j[keep]
    dist = _segment_distances(pts[ends[i, 0]], pts[ends[i, 1]], pts[ends[j, 0]], pts[ends[j, 1]])
    clash = np.flatnonzero(dist < radius[i] + radius[j])
    if clash.size == 0:
        return None
    k = clash[np.argmin(dist[clash] - radius[i[clash]] - radius[j[clash]])]
    return (f"rods through each other: rod {i[k]} (segment {seg[i[k]]}) and rod {j[k]} (segment {seg[j[k]]}) "
            f"are {dist[k]:.3g} cm apart, less than their radii {radius[i[k]] + radius[j[k]]:.3g} cm")


def short_strings(structure: StructureSpec) -> str | None:
    """The first string whose start rest length falls below its floor (pretension too high for its
    stiffness and length), said in words; None if none."""
    pts = structure.node_array()
    for k, s in enumerate(structure.strings):
        mat = structure.string_material(s.tag)
        start_cm = float(norm(pts[s.a] - pts[s.b]))  # fixed arithmetic, the same bits on every CPU
        # pretension in N over stiffness in N/m is metres: x 100 for cm
        rest_cm = start_cm - 100.0 * mat.pretension_n / mat.stiffness_n_per_m
        if rest_cm < mat.min_rest_length_cm:
            return (f"strings cannot hold their pretension: string {k} ({s.tag}) starts {start_cm:.3g} cm long, "
                    f"its rest length {rest_cm:.3g} cm < its floor {mat.min_rest_length_cm:g} cm")
    return None


def static_problem(structure: StructureSpec) -> str | None:
    """Why this body cannot be built as drawn, or None."""
    return crossing_rods(structure) or short_strings(structure)
