"""Ribbed spine (spec 6.4): vertebrae with two 14-rod ribs on 3/4 ellipses, 7 actuated muscles and
4 passive intercostal strings (500 N/m) per joint.

Defined by specs/ribbed.yaml; this module is its named entry point.
"""

from __future__ import annotations

from robot.morphology.model import Morphology
from robot.morphology.specfile import builtin_spec

SPEC = "ribbed"


def ribbed(n_segments: int = 12, *, name: str = SPEC) -> Morphology:
    """NTRT's 2014 configuration: 15 s trials, scored on segment 6, CPG output held 0.1 s."""
    return builtin_spec(SPEC, segments=n_segments, name=name)
