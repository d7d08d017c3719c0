"""Finished trials on their way back: a result with its lease, a batch of them, and the verdicts that
acknowledge each one."""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import StrEnum
from typing import Any

from spinefarm.protocol import limits
from spinefarm.protocol.envelope import get_field
from spinefarm.protocol.errors import MessageError
from spinefarm.protocol.results import TrialResult


@dataclass(frozen=True)
class SubmittedResult:
    """A TrialResult with the lease it answers. `unreadable`: set when decoding, why the result itself could not
    be read although the trial and lease it answers could; `result` is then a failed stand-in with that reason,
    so the coordinator stores the trial as failed instead of refusing the whole batch (and the worker running the
    trial again for ever)."""

    lease_id: int
    result: TrialResult
    unreadable: str = ""
    coordinator: str = ""   # the run instance that leased the trial (WorkGrant.coordinator); another refuses it

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"lease_id": self.lease_id, "result": self.result.to_dict()}
        if self.coordinator:
            d["coordinator"] = self.coordinator
        return d

    @classmethod
    def from_dict(cls, data: Any) -> SubmittedResult:
        item = cls._from_dict(data)   # checks that data is an object
        return replace(item, coordinator=limits.check_text(data.get("coordinator", ""),
                                                           "submitted result field 'coordinator'", 120))

    @classmethod
    def _from_dict(cls, data: Any) -> SubmittedResult:
        raw = get_field(data, "result", dict, "submitted result")
        try:
            result = TrialResult.from_dict(raw)
        except MessageError as exc:
            trial_id = raw.get("trial_id")
            if isinstance(trial_id, bool) or not isinstance(trial_id, int) or trial_id < 0:
                raise  # not even the trial it answers: the message is malformed
            why = str(exc)[:300]
            return cls(get_field(data, "lease_id", int, "submitted result"), unreadable_result(trial_id, why), why)
        if result.trial_id < 0:
            raise MessageError("submitted result has no trial id", received=result.trial_id,
                               expected="a trial id >= 0")
        return cls(get_field(data, "lease_id", int, "submitted result"), result)


def unreadable_result(trial_id: int, why: str) -> TrialResult:
    """A failed stand-in for a result that could not be read (its seed is the coordinator's to fill in)."""
    return TrialResult.failed(f"unreadable result: {why}", -1, trial_id=trial_id)


@dataclass(frozen=True)
class ResultSubmission:
    """A worker returns finished trials; it resends them until each is acknowledged."""

    KIND = "result_submission"
    worker_id: str
    items: tuple[SubmittedResult, ...]

    def to_dict(self) -> dict[str, Any]:
        return {"worker_id": self.worker_id, "items": [i.to_dict() for i in self.items]}

    @classmethod
    def from_dict(cls, data: Any) -> ResultSubmission:
        items = get_field(data, "items", list, "result submission")
        if len(items) > limits.MAX_BATCH:
            raise MessageError("result submission is too large", received=len(items),
                               expected=f"at most {limits.MAX_BATCH} results")
        worker_id = limits.check_id(get_field(data, "worker_id", str, "result submission"),
                                    "result submission worker id")
        return cls(worker_id, tuple(SubmittedResult.from_dict(i) for i in items))


class Verdict(StrEnum):
    """What the coordinator did with one submitted result. Every verdict is final for the worker."""

    STORED = "stored"          # new, stored now
    DUPLICATE = "duplicate"    # already stored (a resend after a lost ack)
    STALE = "stale"            # the lease expired or the trial was re-issued: dropped
    UNKNOWN = "unknown"        # no such trial in this run: dropped
    INVALID = "invalid"        # the result does not fit the trial (e.g. seed mismatch): dropped
    REQUEUED = "requeued"      # timed out or crashed on its worker: issued again (up to 3 attempts in all)


@dataclass(frozen=True)
class ResultAck:
    """Verdicts on submitted results; coordinator: the run instance that gave them (a worker takes a verdict on a
    result from the instance that leased it, or from the one it serves now)."""

    KIND = "result_ack"
    verdicts: tuple[tuple[int, Verdict], ...]
    coordinator: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {"verdicts": [[t, str(v)] for t, v in self.verdicts], "coordinator": self.coordinator}

    @classmethod
    def from_dict(cls, data: Any) -> ResultAck:
        raw = get_field(data, "verdicts", list, "result ack")
        try:
            verdicts = tuple((int(t), Verdict(v)) for t, v in raw)
        except (TypeError, ValueError) as exc:
            raise MessageError("result ack has malformed verdicts", received=raw[:4],
                               expected=f"[trial_id, one of {[v.value for v in Verdict]}] pairs") from exc
        return cls(verdicts, limits.check_text(data.get("coordinator", ""), "result ack field 'coordinator'", 120))

