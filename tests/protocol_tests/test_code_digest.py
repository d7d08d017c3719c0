"""The code digest a worker announces: it changes with any simulating module's source, not with the rest, and
a worker's request carries this install's digest."""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import pytest

from spinefarm.protocol.code_digest import check_digest, code_digest, digest_of, simulating_sources
from spinefarm.protocol.envelope import decode_message, encode_message
from spinefarm.protocol.errors import MessageError
from spinefarm.protocol.work import WorkRequest

PACKAGE = Path(__file__).resolve().parents[2] / "spinefarm"


@pytest.fixture
def package(tmp_path):
    copy = tmp_path / "spinefarm"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__", "*.so", "static", "replay_data"))
    return copy


def test_the_digest_is_a_sha256_of_the_simulating_sources_only(package):
    names = {p.relative_to(package).as_posix() for p in simulating_sources(package)}
    assert {"robot/engines.py", "worker/engines/bullet.py", "worker/control/law.py", "worker/sim/strings.py",
            "worker/trial/simulation.py", "worker/trial/scoring.py"} <= names
    assert not names & {"worker/service/zenoh_worker.py", "coordinator/core.py", "api/app.py"}
    before = digest_of(package)
    assert before == code_digest() and len(before) == 64 and int(before, 16) >= 0
    (package / "worker" / "service" / "zenoh_worker.py").write_text("# transport only\n", encoding="utf-8")
    assert digest_of(package) == before  # the transport does not make other distances
    scoring = package / "worker" / "trial" / "scoring.py"
    scoring.write_bytes(scoring.read_bytes() + b"\n")
    assert digest_of(package) != before  # one byte more in the scoring does
    assert digest_of(package) != hashlib.sha256(b"").hexdigest()


def test_a_request_carries_the_digest_and_a_malformed_one_is_refused():
    req = decode_message(encode_message(WorkRequest("w1", 1, code_digest=code_digest())), WorkRequest)
    assert req.code_digest == code_digest()
    assert decode_message(encode_message(WorkRequest("w1", 1)), WorkRequest).code_digest is None
    with pytest.raises(MessageError, match="not a code digest"):
        check_digest("ABC" * 30, "code_digest")
