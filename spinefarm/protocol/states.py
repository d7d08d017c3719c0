"""The states a trial passes through, and those of its verification and its audit."""

from __future__ import annotations

from enum import StrEnum


class TrialStatus(StrEnum):
    """waiting -> running -> complete | failed(reason). Finished trials never change."""

    WAITING = "waiting"
    RUNNING = "running"
    COMPLETE = "complete"
    FAILED = "failed"

    @property
    def stored(self) -> bytes:
        """The value as the fixed-width byte string storage columns hold."""
        return self.value.encode()


STORED_STATUSES = (TrialStatus.WAITING, TrialStatus.COMPLETE, TrialStatus.FAILED)


class Verification(StrEnum):
    """Re-simulation of a trial that became best, at a finer step. A not-reproduced trial never
    counts as best."""

    NOT_CHECKED = ""
    PENDING = "pending"
    HOLDS = "holds"              # same engine, within tolerance
    JUDGED = "judged"            # in another engine: the judge's distance counts
    NOT_REPRODUCED = "not_reproduced"

    @property
    def stored(self) -> bytes:
        return self.value.encode()


class AuditState(StrEnum):
    """Re-simulation of a result by another worker at the same fidelity."""

    NOT_AUDITED = ""
    PENDING = "pending"
    AGREES = "agrees"            # the auditor measured the same
    DISPUTED = "disputed"        # they differ: a third worker referees
    DISAGREES = "disagrees"      # the referee sided with the auditor: the result (and its worker) is wrong
    OVERRULED = "overruled"      # the referee sided with the result: the auditor is wrong
    QUARANTINED = "quarantined"  # its worker was found wrong elsewhere: re-run by another identity, not trusted

    @property
    def stored(self) -> bytes:
        return self.value.encode()


# A pending audit the run ended without: every live worker was the result's own identity. The row stays pending
# (a resume with another identity runs it); the status, report and API say this.
UNAUDITED = "unaudited (no other worker identity)"
