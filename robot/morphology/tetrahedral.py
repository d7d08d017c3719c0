"""Tetrahedral complex (spec 6.2): 4 rods from a centre, 8 actuated strings per joint, 88 actuators.

Defined by specs/tetrahedral-complex.yaml; this module is its named entry point.
"""

from __future__ import annotations

from robot.morphology.model import Morphology
from robot.morphology.specfile import builtin_spec

SPEC = "tetrahedral-complex"


def tetrahedral_complex(n_segments: int = 12, *, name: str = SPEC) -> Morphology:
    """NTRT's 2014 configuration: V 12 cm/s, A 4000 cm/s^2, node range [-30, 30], CPG every 1 ms."""
    return builtin_spec(SPEC, segments=n_segments, name=name)
