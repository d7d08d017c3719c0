"""Work between a worker and a run's coordinator over Zenoh: the request, the grant with its leased
trials, and the announcement by which workers find a run."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from spinefarm.protocol import limits
from spinefarm.protocol.code_digest import check_digest
from spinefarm.protocol.envelope import FlatMessage, finite, get_field
from spinefarm.protocol.errors import ConfigError, MessageError
from spinefarm.protocol.settings import TaskFidelity
from spinefarm.protocol.submissions import ResultAck, SubmittedResult, Verdict


@dataclass(frozen=True)
class WorkRequest:
    """A worker asks a run for up to `capacity` trials, returning finished ones on the way.

    results: finished trials carried with the request (saves a round trip per batch); the grant's
    verdicts acknowledge them exactly as a ResultAck would.
    """

    KIND = "work_request"
    worker_id: str
    capacity: int
    results: tuple[SubmittedResult, ...] = ()
    engines: tuple[str, ...] | None = None      # the engines this worker can run (None: not said)
    environment: dict[str, str] | None = None   # what this worker runs on (python, packages, CPU)
    code_digest: str | None = None   # its simulating code (protocol.code_digest); None: not said (an old install)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"worker_id": self.worker_id, "capacity": self.capacity,
                             "results": [r.to_dict() for r in self.results]}
        if self.engines is not None:
            d["engines"] = list(self.engines)
        if self.environment is not None:
            d["environment"] = dict(self.environment)
        if self.code_digest is not None:
            d["code_digest"] = self.code_digest
        return d

    @classmethod
    def from_dict(cls, data: Any) -> WorkRequest:
        worker_id = limits.check_id(get_field(data, "worker_id", str, "work request"), "work request worker id")
        capacity = get_field(data, "capacity", int, "work request")
        if not worker_id or not 1 <= capacity <= limits.MAX_BATCH:
            raise MessageError("work request is out of range", received=(worker_id, capacity),
                               expected=f"a non-empty worker id and 1 <= capacity <= {limits.MAX_BATCH}")
        items = get_field(data, "results", list, "work request") if "results" in data else []
        if len(items) > limits.MAX_BATCH:
            raise MessageError("work request carries too many results", received=len(items),
                               expected=f"at most {limits.MAX_BATCH}")
        digest = data.get("code_digest")
        return cls(worker_id, capacity, tuple(SubmittedResult.from_dict(i) for i in items),
                   _engines(data.get("engines")), _environment(data.get("environment")),
                   None if digest is None else check_digest(digest, "work request field 'code_digest'"))


def _engines(value: Any) -> tuple[str, ...] | None:
    if value is None:
        return None
    if not isinstance(value, list) or len(value) > 16 or not all(
            isinstance(e, str) and e.isidentifier() and len(e) <= 32 for e in value):
        raise MessageError("work request field 'engines' is malformed", received=str(value)[:80],
                           expected="a list of at most 16 engine names")
    return tuple(value)


def _environment(value: Any) -> dict[str, str] | None:
    if value is None:
        return None
    if not isinstance(value, dict) or len(value) > 32 or not all(
            isinstance(k, str) and len(k) <= 32 and isinstance(v, str) for k, v in value.items()):
        raise MessageError("work request field 'environment' is malformed", received=str(value)[:80],
                           expected="at most 32 name: text pairs")
    return {k: limits.check_text(v, f"environment entry {k!r}", 200) for k, v in value.items()}


@dataclass(frozen=True)
class TrialAssignment:
    """One leased trial: run `params_unit` (unit cube of the run's space) with `seed`.

    lease_id identifies this issue of the trial; a result must quote it, so a late result for a
    re-issued trial is recognised and dropped. lease_s: time the coordinator waits for it.
    duration_s: simulated seconds of this evaluation (a multi-fidelity rung); None: the run's duration.
    from_start: simulate from step 0 and keep nothing (a check, or a run that turned continuation off); otherwise a
    worker that kept the end of this parameter set's shorter rung goes on from it (worker.trial.continued).
    """

    trial_id: int
    lease_id: int
    params_unit: tuple[float, ...]
    seed: int
    lease_s: float
    duration_s: float | None = None
    fidelity: TaskFidelity | None = None   # a rung's engine / step / settle, or a judge's or audit's task
    from_start: bool = False

    def to_dict(self) -> dict[str, Any]:
        d = {"trial_id": self.trial_id, "lease_id": self.lease_id, "params_unit": list(self.params_unit),
             "seed": self.seed, "lease_s": self.lease_s}
        if self.duration_s is not None:
            d["duration_s"] = self.duration_s
        if self.fidelity is not None:
            d["fidelity"] = self.fidelity.to_dict()
        if self.from_start:
            d["from_start"] = True
        return d

    @classmethod
    def from_dict(cls, data: Any) -> TrialAssignment:
        what = "trial assignment"
        params = get_field(data, "params_unit", list, what)
        if not all(isinstance(p, int | float) and not isinstance(p, bool) for p in params):
            raise MessageError("trial assignment has non-numeric parameters", received=params[:8],
                               expected="a list of numbers in [0, 1]")
        duration = None
        if data.get("duration_s") is not None:
            duration = finite(get_field(data, "duration_s", (int, float), what), "duration_s", what)
            if duration <= 0:
                raise MessageError("trial assignment has a non-positive duration", received=duration,
                                   expected="duration_s > 0 s")
        fidelity = None
        if data.get("fidelity") is not None:
            try:
                fidelity = TaskFidelity.from_dict(get_field(data, "fidelity", dict, what))
            except ConfigError as exc:
                raise MessageError(f"trial assignment has a bad fidelity: {exc}", received=data["fidelity"],
                                   expected="{task, engine, dt_s, settle_s, perturb}") from exc
        return cls(get_field(data, "trial_id", int, what), get_field(data, "lease_id", int, what),
                   tuple(float(p) for p in params), get_field(data, "seed", int, what),
                   finite(get_field(data, "lease_s", (int, float), what), "lease_s", what), duration, fidelity,
                   get_field(data, "from_start", bool, what) if "from_start" in data else False)


@dataclass(frozen=True)
class WorkGrant:
    """The coordinator's answer to a WorkRequest.

    An empty grant says why: `run_done` (budget met, stop asking) or wait `retry_after_s`.
    coordinator: the session of the coordinator holding the run (a worker stays with it while it answers).
    """

    KIND = "work_grant"
    run_id: str
    config_hash: str
    assignments: tuple[TrialAssignment, ...]
    retry_after_s: float = 0.0
    run_done: bool = False
    verdicts: tuple[tuple[int, Verdict], ...] = ()   # for the results the request carried
    coordinator: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {"run_id": self.run_id, "config_hash": self.config_hash,
                "assignments": [a.to_dict() for a in self.assignments],
                "retry_after_s": self.retry_after_s, "run_done": self.run_done,
                "verdicts": ResultAck(self.verdicts).to_dict()["verdicts"], "coordinator": self.coordinator}

    @classmethod
    def from_dict(cls, data: Any) -> WorkGrant:
        what = "work grant"
        items = get_field(data, "assignments", list, what)
        verdicts = ResultAck.from_dict({"verdicts": data.get("verdicts", [])}).verdicts
        return cls(get_field(data, "run_id", str, what), get_field(data, "config_hash", str, what),
                   tuple(TrialAssignment.from_dict(a) for a in items),
                   finite(get_field(data, "retry_after_s", (int, float), what), "retry_after_s", what),
                   get_field(data, "run_done", bool, what), verdicts,
                   limits.check_text(data.get("coordinator", ""), "work grant field 'coordinator'", 120))


@dataclass(frozen=True)
class RunInfo(FlatMessage):
    """A coordinator announces its run so stateless workers can find it."""

    KIND = "run_info"
    WHAT = "run info"
    run_id: str
    config_hash: str
    trials_budget: int
    run_done: bool

