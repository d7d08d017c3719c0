"""The states a trial passes through, those of its verification and its audit, and the kinds of run that check it."""

from __future__ import annotations

from enum import StrEnum

from spinefarm.protocol.errors import StorageError


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
    """Re-simulation of a trial that became best, at a finer step (or in another engine). The judged
    distance is the one that counts; a set whose judge run diverged never counts as best."""

    NOT_CHECKED = ""
    PENDING = "pending"
    HOLDS = "holds"              # same engine, within the robot's chaos floor
    MOVED = "moved"              # same engine, moved more than that: kept, ranked by the judged distance
    JUDGED = "judged"            # in another engine: the judge's distance counts
    DIVERGED = "diverged"        # the judge's run failed or gave no finite distance: never best
    NOT_REPRODUCED = "not_reproduced"   # older run files (a fixed 5 % tolerance): never best

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


class EvaluationKind(StrEnum):
    """What a run beside the screen's own rows did (the `kind` of an evaluation row, storage.evaluations; the kind
    of a check's lease, coordinator.ladder.keys). The one spelling of these names."""

    JUDGE = "judge"        # a finer step or another engine: its distance counts
    AUDIT = "audit"        # another worker at the same fidelity
    REFEREE = "referee"    # a third worker on a disputed audit
    OPINION = "opinion"    # a judged best in the other engine at its converged step: never ranks

    @property
    def stored(self) -> bytes:
        return self.value.encode()

    @classmethod
    def of(cls, name: object) -> EvaluationKind:
        """The kind named `name` (str or stored bytes); anything else is refused in one line naming it."""
        try:
            return cls(name.decode() if isinstance(name, bytes) else name)
        except (ValueError, UnicodeDecodeError):
            raise StorageError("unknown evaluation kind", received=name,
                               expected="one of " + ", ".join(k.value for k in cls)) from None


# verdicts after which the judged distance is the set's figure (it ranks by it)
JUDGED_VERDICTS = (Verification.HOLDS.stored, Verification.MOVED.stored, Verification.JUDGED.stored)
# verdicts that keep a set from ever being best
REFUTED_VERDICTS = (Verification.DIVERGED.stored, Verification.NOT_REPRODUCED.stored)

# A pending audit the run ended without: every live worker was the result's own identity. The row stays pending
# (a resume with another identity runs it); the status, report and API say this.
UNAUDITED = "unaudited (no other worker identity)"
