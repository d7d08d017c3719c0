"""Controller parameter spaces: a ParamSpace plus the map from physical values to a CpgNetwork.

Two spaces:
- "ntrt": NTRT's code (spec 4.4, 4.5). One node parameter pair (frequency and amplitude
  coefficients, each used as both offset and gain, so with the descending command d = 2 the
  intrinsic frequency is 3 f Hz and the target amplitude 3 A cm/s) and one (weight, phase) pair
  per slot of the coupling table E[rp][j][k], 2 + 2 N_e parameters.
- "sidewinding": the paper's 9-parameter Tetraspine space (section IV-A); see SidewindingSpace.
- "ntrt-followable": NTRT's space with node bounds a motor can follow; see NtrtFollowableSpace.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from spinefarm.protocol.errors import ConfigError, MorphologySpecError
from spinefarm.protocol.params import ParamSpace, ParamSpec
from spinefarm.robot.cpg_network import CpgNetwork

if TYPE_CHECKING:
    from spinefarm.robot.morphology.model import Morphology


class BaseControllerSpace:
    """A seam: `param_space` is read when a search starts; `network(physical)` at each trial start."""

    name: str
    param_space: ParamSpace

    def network(self, physical: np.ndarray) -> CpgNetwork:
        raise NotImplementedError


def _shares_body(morph: Morphology, s1: int, s2: int) -> bool:
    seg = morph.structure.node_segment
    a = morph.structure.strings[s1]
    b = morph.structure.strings[s2]
    return bool({seg[a.a], seg[a.b]} & {seg[b.a], seg[b.b]})


def table_slots(m_per_joint: int) -> list[tuple[int, int, int]]:
    """Coupling-table slots (rp, j, k), rp 0..2, k >= j, skipping (1, j, j); N_e = 3 M (M+1)/2 - M."""
    return [(rp, j, k) for rp in range(3) for j in range(m_per_joint) for k in range(j, m_per_joint)
            if not (rp == 1 and j == k)]


@dataclass(frozen=True)
class Coupling:
    target: int
    source: int
    slot: int


def ntrt_couplings(morph: Morphology, node_strings: list[int], m_per_joint: int) -> list[Coupling]:
    """Directed couplings m <- t between nodes whose strings share a body, with NTRT's slot quirk:
    rp = trunc((m - t) / M) + 1 from the index difference, slot E[rp][min(j, k)][max(j, k)]."""
    slot_index = {s: i for i, s in enumerate(table_slots(m_per_joint))}
    out = []
    for m, sm in enumerate(node_strings):
        for t, st in enumerate(node_strings):
            if t == m or not _shares_body(morph, sm, st):
                continue
            rp = int((m - t) / m_per_joint) + 1  # int() truncates toward zero like C
            j, k = m % m_per_joint, t % m_per_joint
            out.append(Coupling(m, t, slot_index[(rp, min(j, k), max(j, k))]))
    return out


def _csr(n_nodes: int, targets: np.ndarray, sources: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    order = np.lexsort((sources, targets))
    indptr = np.zeros(n_nodes + 1, dtype=np.int64)
    np.add.at(indptr, targets + 1, 1)
    return np.cumsum(indptr), sources[order].astype(np.int64), order


class NtrtTableSpace(BaseControllerSpace):
    """NTRT's per-coupling space: parameter order is [frequency, amplitude, then (weight, phase)
    for each table slot in lexicographic (rp, j, k) order]. NTRT's edge file i fills slot N_e-1-i."""

    name = "ntrt"

    def __init__(self, morph: Morphology) -> None:
        self.morph = morph
        tags = set(morph.control.cpg_tags)
        self.node_strings = [i for i, s in enumerate(morph.structure.strings) if s.tag in tags]
        joints = morph.joint_of_string()
        per_joint: dict[int, int] = {}
        for i in self.node_strings:
            per_joint[joints[i]] = per_joint.get(joints[i], 0) + 1
        counts = set(per_joint.values())
        if len(counts) != 1:
            raise MorphologySpecError("the NTRT controller space needs the same number of CPG strings "
                                      "per joint", received=per_joint, expected="one count for all joints")
        self.m_per_joint = counts.pop()
        self.slots = table_slots(self.m_per_joint)
        self.couplings = ntrt_couplings(morph, self.node_strings, self.m_per_joint)
        lo, hi = morph.control.node_range
        specs = [
            ParamSpec("cpg_frequency_coef_hz", lo, hi, "Hz",
                      "node frequency offset = gain; intrinsic frequency = (1 + d) * value with d = 2"),
            ParamSpec("cpg_amplitude_coef_cm_s", lo, hi, "cm/s",
                      "node amplitude offset = gain; target amplitude = (1 + d) * value"),
        ]
        for rp, j, k in self.slots:
            specs.append(ParamSpec(f"coupling_r{rp}_{j}_{k}_weight", 0.0, 1.0, "",
                                   f"coupling weight of table slot E[{rp}][{j}][{k}]"))
            specs.append(ParamSpec(f"coupling_r{rp}_{j}_{k}_phase_rad", -math.pi, math.pi, "rad",
                                   f"phase offset of table slot E[{rp}][{j}][{k}]"))
        self.param_space = ParamSpace(f"{morph.name}/ntrt", tuple(specs))

    @property
    def n_edges(self) -> int:
        return len(self.slots)

    def network(self, physical: np.ndarray) -> CpgNetwork:
        x = np.asarray(physical, dtype=float)
        d = self.morph.control.descending_command
        f, amp = x[0], x[1]
        weights = x[2::2]
        phases = x[3::2]
        n = len(self.node_strings)
        tgt = np.array([c.target for c in self.couplings], dtype=np.int64)
        src = np.array([c.source for c in self.couplings], dtype=np.int64)
        slot = np.array([c.slot for c in self.couplings], dtype=np.int64)
        indptr, source, order = _csr(n, tgt, src)
        return CpgNetwork(
            node_string=np.array(self.node_strings, dtype=np.int64),
            omega_rad_s=np.full(n, 2.0 * math.pi * (f * d + f)),
            amplitude_cm_s=np.full(n, amp * d + amp),
            indptr=indptr, source=source, weight=weights[slot][order], phase_rad=phases[slot][order],
            amplitude_rate_per_s=self.morph.control.amplitude_rate_per_s,
        )

    def unit_from_ntrt_files(self, node: tuple[float, float], edges: list[tuple[float, float]]) -> np.ndarray:
        """Unit-cube vector from NTRT's published values: node pair and edge file pairs in file order."""
        if len(edges) != self.n_edges:
            raise ConfigError("wrong number of NTRT edge files", received=len(edges),
                              expected=f"{self.n_edges} for {self.morph.name}")
        u = [node[0], node[1]]
        for slot in range(self.n_edges):
            u.extend(edges[self.n_edges - 1 - slot])
        return np.array(u, dtype=float)


class SidewindingSpace(BaseControllerSpace):
    """The paper's 9-parameter Tetraspine space (section IV-A), as we read it.

    Only the three outer strings of each joint (right, left, top) carry CPG nodes; the inner strings
    stay under impedance control with a zero velocity setpoint (Fig. 3 caption). Nodes are
    homogeneous: frequency = f0 + f1 d and amplitude = a0 + a1 d with the descending command d a
    learned constant held through the trial ("commands were held constant"). Four connections per
    segment, weight 0.5 each way, the reverse direction using the negated phase (symmetric
    couplings): right-left within a joint, and right, left and top to the same string of the next
    joint. 4 node values + 1 command + 4 phases = 9.
    """

    name = "sidewinding"
    WEIGHT = 0.5

    def __init__(self, morph: Morphology) -> None:
        self.morph = morph
        joints = morph.joint_of_string()
        outer = [i for i, s in enumerate(morph.structure.strings) if s.tag == "outer"]
        if not outer:
            raise MorphologySpecError("the sidewinding space needs strings tagged 'outer'",
                                      received=sorted({s.tag for s in morph.structure.strings}),
                                      expected="a Tetraspine-like structure")
        self.node_strings = outer
        # (joint, local index) of each node: 0 right, 1 left, 2 top
        self.node_key = []
        seen: dict[int, int] = {}
        for i in outer:
            j = joints[i]
            self.node_key.append((j, seen.get(j, 0)))
            seen[j] = seen.get(j, 0) + 1
        specs = (
            ParamSpec("frequency_offset_hz", 0.0, 1.0, "Hz", "node frequency offset f0"),
            ParamSpec("frequency_gain_hz", 0.0, 1.0, "Hz", "node frequency gain f1 on the command"),
            ParamSpec("amplitude_offset_cm_s", 0.0, 20.0, "cm/s", "node amplitude offset a0"),
            ParamSpec("amplitude_gain_cm_s", 0.0, 20.0, "cm/s", "node amplitude gain a1 on the command"),
            ParamSpec("descending_command", 0.0, 2.0, "", "constant descending command d"),
            ParamSpec("phase_right_left_rad", -math.pi, math.pi, "rad", "right -> left, same joint"),
            ParamSpec("phase_right_next_rad", -math.pi, math.pi, "rad", "right -> right of next joint"),
            ParamSpec("phase_left_next_rad", -math.pi, math.pi, "rad", "left -> left of next joint"),
            ParamSpec("phase_top_next_rad", -math.pi, math.pi, "rad", "top -> top of next joint"),
        )
        self.param_space = ParamSpace(f"{morph.name}/sidewinding", specs)

    def network(self, physical: np.ndarray) -> CpgNetwork:
        f0, f1, a0, a1, d, p_rl, p_rn, p_ln, p_tn = (float(v) for v in physical)
        index = {key: n for n, key in enumerate(self.node_key)}
        edges: list[tuple[int, int, float]] = []  # (target, source, psi)

        def link(a: tuple[int, int], b: tuple[int, int], psi: float) -> None:
            if a in index and b in index:
                # lock phi_b = phi_a + psi: a node taking psi from t settles at phi_t - psi
                edges.append((index[b], index[a], -psi))
                edges.append((index[a], index[b], psi))

        n_joints = max(j for j, _ in self.node_key) + 1
        for j in range(n_joints):
            link((j, 0), (j, 1), p_rl)
            link((j, 0), (j + 1, 0), p_rn)
            link((j, 1), (j + 1, 1), p_ln)
            link((j, 2), (j + 1, 2), p_tn)
        n = len(self.node_strings)
        tgt = np.array([e[0] for e in edges], dtype=np.int64)
        src = np.array([e[1] for e in edges], dtype=np.int64)
        psi = np.array([e[2] for e in edges])
        indptr, source, order = _csr(n, tgt, src)
        return CpgNetwork(
            node_string=np.array(self.node_strings, dtype=np.int64),
            omega_rad_s=np.full(n, 2.0 * math.pi * (f0 + f1 * d)),
            amplitude_cm_s=np.full(n, a0 + a1 * d),
            indptr=indptr, source=source, weight=np.full(len(edges), self.WEIGHT), phase_rad=psi[order],
            amplitude_rate_per_s=self.morph.control.amplitude_rate_per_s,
        )


def followable_limits(morph: Morphology, node_strings: list[int]) -> tuple[float, float]:
    """(highest intrinsic frequency Hz, highest target amplitude cm/s) the CPG strings' motors can follow.

    The impedance law turns a velocity setpoint V0 = a cos(2 pi f t) into a tension target that moves
    by B a, which the motor produces by moving the rest length by B a / k: a motion of speed
    2 pi f B a / k. It can follow while that stays below the motor speed V, and the setpoint itself
    while a <= V; with a up to V this leaves f <= k / (2 pi B) (1.6 Hz for k = 1000 N/m, B = 100 N s/m).
    The motor's acceleration limit allows 2 pi f V <= A (66 Hz at the paper's limits), and a CPG output
    held for a period P samples f <= 1 / (2 P). The tightest string decides.
    """
    gains = dict(morph.control.impedance)
    f_max, a_max = math.inf, math.inf
    for i in node_strings:
        string = morph.structure.strings[i]
        mat = dict(morph.structure.string_materials)[string.tag]
        imp = gains[string.tag]
        v, k, b = mat.motor_speed_cm_s, mat.stiffness_n_per_m, imp.velocity_gain_n_s_per_m
        a_max = min(a_max, v)
        if b > 0:
            f_max = min(f_max, k / (2.0 * math.pi * b))
        f_max = min(f_max, mat.motor_accel_cm_s2 / (2.0 * math.pi * v))
    f_max = min(f_max, 1.0 / (2.0 * morph.control.cpg_update_period_s))
    return f_max, a_max


class NtrtFollowableSpace(NtrtTableSpace):
    """NTRT's space with the node parameters bounded to what the motors can follow (followable_limits).

    NTRT's node range (0..30 for most robots) asks for intrinsic frequencies up to 90 Hz and
    amplitudes up to 90 cm/s with d = 2, far beyond a motor of 24 cm/s; here the frequency and
    amplitude coefficients span [0, f_max / (1 + d)] and [0, a_max / (1 + d)] (mirrored to negative
    values when the robot's node range is), so every node target is one the motor can follow. The
    couplings are NTRT's. Allowed wherever the `ntrt` space is.
    """

    name = "ntrt-followable"
    base = "ntrt"

    def __init__(self, morph: Morphology) -> None:
        super().__init__(morph)
        f_max, a_max = followable_limits(morph, self.node_strings)
        scale = 1.0 + morph.control.descending_command
        mirrored = morph.control.node_range[0] < 0
        specs = list(self.param_space.specs)
        for idx, top in ((0, f_max / scale), (1, a_max / scale)):
            old = specs[idx]
            specs[idx] = ParamSpec(old.name, -top if mirrored else 0.0, top, old.unit,
                                   old.doc + "; bounded to what the motor can follow")
        self.param_space = ParamSpace(f"{morph.name}/{self.name}", tuple(specs))


SPACES: dict[str, type[BaseControllerSpace]] = {"ntrt": NtrtTableSpace, "sidewinding": SidewindingSpace,
                                                NtrtFollowableSpace.name: NtrtFollowableSpace}


def controller_space(morph: Morphology, controller: str | None = None) -> BaseControllerSpace:
    """`morph`'s controller space `controller` (None: the first it lists): one it lists, or a bounded variant
    of one (a space's `base`: it is allowed as its base is)."""
    name = controller or morph.controllers[0]
    space = SPACES.get(name)
    if name not in morph.controllers and getattr(space, "base", name) not in morph.controllers:
        raise ConfigError(f"morphology {morph.name!r} has no controller space {name!r}",
                          received=name, expected=list(morph.controllers))
    if space is None:
        raise ConfigError("unknown controller space", received=name, expected=sorted(SPACES))
    return space(morph)


def param_space(morph: Morphology, controller: str | None = None) -> ParamSpace:
    """The parameters of `morph`'s controller space `controller` (None: the first it lists)."""
    return controller_space(morph, controller).param_space
