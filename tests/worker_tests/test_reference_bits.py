"""The distances recorded before the loop was rewritten (reference_bits.py) hold to the bit: NTRT's replays and
the shipped gaits on Bullet and MuJoCo (2 s), and a 2 ms MuJoCo screen without segment contacts."""

from __future__ import annotations

import contextlib
import io
import json

import pytest

from spinefarm.cli.main import main
from tests.worker_tests.reference_bits import DATA, cases, distances

REFERENCE = json.loads(DATA.read_text())


@pytest.mark.parametrize("name", sorted(cases()))
def test_distances_are_the_recorded_bits(name):
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(cases()[name]) == 0
    assert distances(json.loads(out.getvalue().strip().splitlines()[-1])) == REFERENCE[name]
