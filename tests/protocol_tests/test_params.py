from __future__ import annotations

import math

import numpy as np
import pytest

from spinefarm.protocol.errors import ParameterError
from spinefarm.protocol.params import ParamSpace, ParamSpec
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.spaces import controller_space, param_space


def space() -> ParamSpace:
    return ParamSpace("s", (ParamSpec("f_hz", 0.0, 30.0, "Hz"), ParamSpec("psi_rad", -math.pi, math.pi, "rad")))


def test_unit_cube_round_trip():
    s = space()
    u = np.array([0.25, 0.75])
    x = s.from_unit(u)
    assert np.allclose(x, [7.5, math.pi / 2])
    assert np.allclose(s.to_unit(x), u)
    assert s.from_named(s.to_named(x)).tolist() == x.tolist()


@pytest.mark.parametrize("vector, words", [([0.1], "wrong length"), ([0.1, float("nan")], "non-finite"),
                                           ([0.1, 1.5], "outside [0, 1]"), (["a", 1], "not numeric")])
def test_bad_vectors_are_named(vector, words):
    with pytest.raises(ParameterError) as exc:
        space().from_unit(vector)
    assert words in str(exc.value)
    assert "expected" in str(exc.value)


def test_ntrt_tetraspine_space_counts():
    morph = load_morphology("tetraspine-ntrt")
    sp = controller_space(morph, "ntrt")
    assert len(sp.param_space) == 116 and sp.n_edges == 57
    assert len(sp.couplings) == 132  # 12 nodes x 11
    assert len(param_space(load_morphology("tetraspine"), "sidewinding")) == 9


def test_ntrt_slot_quirk():
    """rp from the index difference: a pair in adjacent joints closer than M in index uses row 1."""
    from spinefarm.robot.spaces import table_slots

    sp = controller_space(load_morphology("tetraspine-ntrt"), "ntrt")
    slots = table_slots(6)
    by_pair = {(c.target, c.source): slots[c.slot] for c in sp.couplings}
    assert by_pair[(7, 2)] == (1, 1, 2)  # index difference 5 < M = 6, joints 1 and 0
    assert by_pair[(6, 0)] == (2, 0, 0) and by_pair[(0, 6)] == (0, 0, 0)
    assert slots[0] == (0, 0, 0) and (1, 0, 0) not in slots


def test_edge_file_order_is_reversed_into_slots():
    sp = controller_space(load_morphology("tetraspine-ntrt"), "ntrt")
    edges = [(i / 100, 1 - i / 100) for i in range(sp.n_edges)]
    u = sp.unit_from_ntrt_files((0.1, 0.2), edges)
    assert u[0] == 0.1 and u[1] == 0.2
    assert tuple(u[2:4]) == edges[-1]  # slot 0 takes the last edge file
    assert tuple(u[-2:]) == edges[0]
