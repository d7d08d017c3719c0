"""A trial result's notes (extras) and the protocol's limit on them: a note too long made the coordinator refuse
the worker's whole result batch, so the worker cuts every note to the limit before it sends."""

from __future__ import annotations

import pytest

from spinefarm.protocol.errors import MessageError
from spinefarm.protocol.results import MAX_EXTRA_TEXT_CHARS, TrialResult, fit_extras
from spinefarm.protocol.states import TrialStatus


def result(extras: dict) -> TrialResult:
    return TrialResult(TrialStatus.COMPLETE, "", 0.1, 1.0, 0.5, 3.0, 0.1, 2.0, 1.0, 29.5, 7, extras=extras)


def test_a_long_note_is_cut_to_what_the_protocol_carries():
    note = "modelled: " + "x" * 200
    with pytest.raises(MessageError, match="'extras' is malformed"):
        TrialResult.from_dict(result({"segment_contacts": note, "dt_s": 0.001}).to_dict())
    fitted = fit_extras({"segment_contacts": note, "dt_s": 0.001, "engine": "mujoco"})
    assert len(fitted["segment_contacts"]) == MAX_EXTRA_TEXT_CHARS
    assert fitted["segment_contacts"] == note[:MAX_EXTRA_TEXT_CHARS - 1] + "…"
    assert fitted["dt_s"] == 0.001 and fitted["engine"] == "mujoco"  # numbers and short texts as they were
    assert TrialResult.from_dict(result(fitted).to_dict()).extras == fitted


def test_a_failed_trial_with_a_long_reason_is_sent_with_it_cut():
    from spinefarm.protocol import limits
    from spinefarm.protocol.results import fit_for_protocol

    long = result({"engine": "mujoco", "note": "y" * 100})
    long = TrialResult(TrialStatus.FAILED, "error: " + "z" * 3000, *[float("nan")] * 7, 29.5, 7,
                       extras=long.extras)
    with pytest.raises(MessageError, match="'reason' is too long"):
        TrialResult.from_dict(long.to_dict())
    sent = TrialResult.from_dict(fit_for_protocol(long).to_dict())
    assert len(sent.reason) == limits.MAX_TEXT_CHARS and sent.reason.startswith("error: zzz")
    assert sent.extras == {"engine": "mujoco", "note": "y" * (MAX_EXTRA_TEXT_CHARS - 1) + "…"}
