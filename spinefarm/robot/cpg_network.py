"""A CPG network as data: which string each oscillator drives, its frequency and amplitude, and the
sparse phase couplings. Engine- and compiler-free, so a coordinator can build one to check a space."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CpgNetwork:
    """A CPG: node_string (n,) string driven by each node; omega_rad_s (n,); amplitude_cm_s (n,)
    target amplitudes R; CSR coupling (indptr (n+1,), source (e,), weight (e,), phase_rad (e,))
    where row m lists the sources t that node m takes a term from."""

    node_string: np.ndarray
    omega_rad_s: np.ndarray
    amplitude_cm_s: np.ndarray
    indptr: np.ndarray
    source: np.ndarray
    weight: np.ndarray
    phase_rad: np.ndarray
    amplitude_rate_per_s: float = 20.0

    @property
    def n_nodes(self) -> int:
        return int(self.node_string.shape[0])

    @property
    def n_couplings(self) -> int:
        return int(self.source.shape[0])

    def fastest_rate_per_s(self) -> float:
        """A bound on how fast any part of the state moves (1/s): the largest |omega_i| plus the coupling
        gain sum_j |w_ij| R_j a node can feel, or the amplitude rate if larger (worker.control.cpg uses it
        to size RK4 sub-steps)."""
        gain = np.zeros(self.n_nodes)
        rows = np.repeat(np.arange(self.n_nodes), np.diff(self.indptr))
        np.add.at(gain, rows, np.abs(self.weight) * np.abs(self.amplitude_cm_s[self.source]))
        return float(max(np.max(np.abs(self.omega_rad_s) + gain, initial=0.0), self.amplitude_rate_per_s))

    def complex_weights(self) -> np.ndarray:
        """w e^{-i psi} per edge, from glibc's cos and sin (math): the same bits on every CPU."""
        pairs = zip(self.weight.tolist(), self.phase_rad.tolist(), strict=True)
        return np.array([complex(w * math.cos(p), -w * math.sin(p)) for w, p in pairs], dtype=np.complex128)
