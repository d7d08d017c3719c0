"""Tetraspine (spec 6.1): tetrahedral segments, six actuated strings per joint.

The paper simulated 12 segments; NTRT's code (and the hardware) has 3. Segment i is the
base tetrahedron shifted by -(i + 1) * 0.75 e along z, so segment 0 sits at the largest z.
"""

from __future__ import annotations

from robot.morphology.model import ControlSpec, ImpedanceGains, Morphology
from robot.morphology.structure import Rod, RodMaterial, String, StringMaterial, StructureSpec

EDGE_CM = 38.1
HEIGHT_CM = 32.99557  # round5(sqrt(3)/2 * e)
FRONT_Z_CM = 28.575  # round5(sqrt(3)/2 * h)
SPACING_CM = 28.575  # 0.75 e

# Per joint, in CPG order: (node on segment s, node on segment s + 1, tag)
JOINT_STRINGS = (
    (0, 0, "outer"),  # outer right
    (1, 1, "outer"),  # outer left
    (2, 2, "outer"),  # outer top
    (0, 3, "inner"),  # inner right
    (1, 3, "inner"),  # inner left
    (2, 3, "inner"),  # inner top
)
RODS = ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))
NODE_NAMES = ("right", "left", "top", "front")


def tetraspine_structure(n_segments: int = 12, *, name: str = "tetraspine",
                         rod: RodMaterial | None = None, string: StringMaterial | None = None,
                         edge_cm: float = EDGE_CM) -> StructureSpec:
    scale = edge_cm / EDGE_CM
    local = [(-19.05 * scale, 0.0, 0.0), (19.05 * scale, 0.0, 0.0), (0.0, HEIGHT_CM * scale, 0.0),
             (0.0, HEIGHT_CM * scale / 2, FRONT_Z_CM * scale)]
    nodes, node_seg, names, rods, strings = [], [], [], [], []
    for s in range(n_segments):
        dz = 100.0 - (s + 1) * SPACING_CM * scale
        for k, (x, y, z) in enumerate(local):
            nodes.append((x, y + 2.0, z + dz))
            node_seg.append(s)
            names.append(f"s{s}.{NODE_NAMES[k]}")
        rods.extend(Rod(4 * s + a, 4 * s + b, "rod") for a, b in RODS)
    for s in range(n_segments - 1):
        strings.extend(String(4 * s + a, 4 * (s + 1) + b, tag) for a, b, tag in JOINT_STRINGS)
    rod = rod or RodMaterial(radius_cm=0.5, density_kg_per_cm3=4.2 / 300, friction=1.0)
    string = string or StringMaterial()
    return StructureSpec(
        name=name, nodes=tuple(nodes), node_segment=tuple(node_seg), node_names=tuple(names),
        rods=tuple(rods), strings=tuple(strings), rod_materials=(("rod", rod),),
        string_materials=(("inner", string), ("outer", string)),
    )


def tetraspine(n_segments: int = 12, *, name: str = "tetraspine", duration_s: float = 30.0) -> Morphology:
    """The paper's 12-segment Tetraspine with NTRT's 2014 materials, gains and control lengths."""
    control = ControlSpec(
        cpg_tags=("inner", "outer"),
        impedance=(("inner", ImpedanceGains(0.0, 1000.0, 100.0, 15.0)),
                   ("outer", ImpedanceGains(0.0, 1000.0, 100.0, 17.0))),
        cpg_update_period_s=0.001, node_range=(0.0, 30.0),
    )
    return Morphology(
        name=name, structure=tetraspine_structure(n_segments, name=name), control=control,
        scored_segment=n_segments // 2, duration_s=duration_s, ground_friction=0.5,
        controllers=("ntrt", "sidewinding"),
        description=f"Tetraspine, {n_segments} tetrahedral segments, 6 actuated strings per joint",
    )


HARDWARE_SEGMENT_KG = 0.73
HARDWARE_ROD_RADIUS_CM = 0.32
HARDWARE_STIFFNESS_N_PER_M = 600_000.0


def tetraspine_hardware() -> Morphology:
    """The 3-segment hardware prototype of paper section V: 38.1 cm carbon rods of 0.64 cm diameter,
    0.73 kg segments (boards included, spread over the rods), and vectran cables without in-line
    springs, about 600 times stiffer than the simulated strings. Needs a step well below 1 ms."""
    rod_length_cm = 5 * EDGE_CM + HEIGHT_CM
    density = HARDWARE_SEGMENT_KG / (3.141592653589793 * HARDWARE_ROD_RADIUS_CM**2 * rod_length_cm)
    base = tetraspine(3, name="tetraspine-hardware")
    structure = tetraspine_structure(
        3, name="tetraspine-hardware",
        rod=RodMaterial(radius_cm=HARDWARE_ROD_RADIUS_CM, density_kg_per_cm3=density, friction=1.0),
        string=StringMaterial(stiffness_n_per_m=HARDWARE_STIFFNESS_N_PER_M))
    return Morphology(
        name="tetraspine-hardware", structure=structure, control=base.control, scored_segment=1,
        duration_s=30.0, ground_friction=0.5, controllers=base.controllers,
        description="3-segment hardware Tetraspine (paper section V): 0.73 kg segments, ~600,000 N/m cables",
    )
