"""Envelopes are exact: the schema version is the integer 1 (not 1.0, not true) and no object repeats a key."""

from __future__ import annotations

import pytest

from spinefarm.protocol.envelope import decode
from tests.coordinator_tests.helpers import sphere_core
from tests.coordinator_tests.test_core import ask
from tests.coordinator_tests.test_hostile_peers import assert_unchanged, snapshot

BAD = {
    "schema 1.0": b'{"schema":1.0,"kind":"work_request","body":{"worker_id":"w","capacity":1}}',
    "schema true": b'{"schema":true,"kind":"work_request","body":{"worker_id":"w","capacity":1}}',
    "duplicate envelope key": b'{"schema":1,"kind":"work_request","kind":"work_request",'
                              b'"body":{"worker_id":"w","capacity":1}}',
    "duplicate body key": b'{"schema":1,"kind":"work_request","body":{"worker_id":"w","worker_id":"v","capacity":1}}',
}


@pytest.mark.parametrize("name", sorted(BAD))
def test_inexact_envelopes_get_an_error_and_no_grant(name):
    core, storage, _ = sphere_core(trials=10)
    ask(core)
    before = snapshot(storage)
    kind, body = decode(core.handle_work(BAD[name]))
    assert kind == "error" and body["code"] == "malformed_message", body
    assert_unchanged(before, storage)
    assert core.status()["rejected_messages"] == 1
