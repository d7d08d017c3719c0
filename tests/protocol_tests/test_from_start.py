"""TrialAssignment.from_start on the wire: sent only when set, read back, absent means False (a coordinator that
predates it), anything but a boolean refused naming what it got."""

from __future__ import annotations

import pytest

from spinefarm.protocol.errors import MessageError
from spinefarm.protocol.work import TrialAssignment


def test_from_start_goes_over_the_wire_only_when_set():
    plain = TrialAssignment(3, 7, (0.25, 0.5), 11, 60.0, 10.0)
    assert "from_start" not in plain.to_dict() and TrialAssignment.from_dict(plain.to_dict()) == plain
    fresh = TrialAssignment(3, 7, (0.25, 0.5), 11, 60.0, 10.0, None, True)
    assert fresh.to_dict()["from_start"] is True and TrialAssignment.from_dict(fresh.to_dict()).from_start


def test_a_from_start_that_is_not_a_boolean_is_refused():
    data = {**TrialAssignment(3, 7, (0.25,), 11, 60.0).to_dict(), "from_start": "yes"}
    with pytest.raises(MessageError, match=r"from_start.*wrong type") as err:
        TrialAssignment.from_dict(data)
    assert "yes" in str(err.value) and "bool" in str(err.value)
