"""The docs' figures are what their commands print (tests/docs_check.py; `make docs-check` runs them all)."""

from __future__ import annotations

import pytest

from tests.docs_check import CHECKS, _flat, run_check


def test_a_changed_figure_is_noticed():
    """The check formats the command's figures into the doc's sentence: a figure one digit off is not found."""
    sentence = CHECKS["ribbed"][2]
    figures = {"distance_m": 1.5794062270204956, "speed_cm_s": 10.529374846803304, "cot": 10.75690398332192}
    assert _flat(sentence.format(**figures)) == "ribbed 1.5794062270204956 m, 10.53 cm/s, COT 10.76"
    cache = {CHECKS["ribbed"][1]: dict(figures, distance_m=1.5794062270205)}
    assert run_check("ribbed", cache)["ok"] is False
    cache = {CHECKS["ribbed"][1]: figures}
    assert run_check("ribbed", cache)["ok"] is True  # the figures `spinefarm trial` gave when the doc was written


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(CHECKS))
def test_the_docs_say_what_their_commands_print(name):
    result = run_check(name, {})
    assert result["ok"], result
