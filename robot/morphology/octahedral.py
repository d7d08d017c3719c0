"""Cross-linked octahedral complex (spec 6.3): 6 rods from a centre, alternately rotated segments,
4 driven passive ligaments and 4 CPG strings per joint, CPG output held 0.1 s.

Defined by specs/octahedral-complex.yaml; this module is its named entry point.
"""

from __future__ import annotations

from robot.morphology.model import Morphology
from robot.morphology.specfile import builtin_spec

SPEC = "octahedral-complex"


def octahedral_complex(n_segments: int = 12, *, name: str = SPEC) -> Morphology:
    """NTRT's 2014 configuration: impedance K 400, B 40; ligaments k 2000 driven to start - 0.5 cm."""
    return builtin_spec(SPEC, segments=n_segments, name=name)
