"""Variants of a morphology with changed materials or gains (for studies, benchmarks and tests)."""

from __future__ import annotations

import dataclasses

from spinefarm.robot.morphology.model import Morphology


def with_strings(morph: Morphology, **changes: float) -> Morphology:
    """Every string material changed, e.g. with_strings(m, stiffness_n_per_m=600_000.0)."""
    mats = tuple((t, dataclasses.replace(m, **changes)) for t, m in morph.structure.string_materials)
    return dataclasses.replace(morph, structure=dataclasses.replace(morph.structure, string_materials=mats))


def with_density_factor(morph: Morphology, factor: float) -> Morphology:
    """Every rod's density multiplied by `factor` (lighter or heavier segments, same geometry)."""
    mats = tuple((t, dataclasses.replace(m, density_kg_per_cm3=m.density_kg_per_cm3 * factor))
                 for t, m in morph.structure.rod_materials)
    return dataclasses.replace(morph, structure=dataclasses.replace(morph.structure, rod_materials=mats))


def with_gains(morph: Morphology, **changes: float | None) -> Morphology:
    """Every impedance entry changed, e.g. with_gains(m, control_length_cm=None)."""
    imp = tuple((t, dataclasses.replace(g, **changes)) for t, g in morph.control.impedance)
    return dataclasses.replace(morph, control=dataclasses.replace(morph.control, impedance=imp))
