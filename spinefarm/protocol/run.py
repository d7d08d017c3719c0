"""The run as data: one object holds everything a stateless worker needs to run trials of a run.

The morphology spec (not a name) is the authority: workers build the robot and its parameter space
from it and check the three hashes below against what they built, so a run can never mix two robots.
It is stored once in the run file and a resumed run is rebuilt from it, even if a built-in changed.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, field
from typing import Any

from spinefarm.protocol.envelope import finite_or_str, get_field, json_default
from spinefarm.protocol.errors import MessageError
from spinefarm.protocol.params import ParamSpace, ParamSpec


def json_hash(obj: Any) -> str:
    """16 hex digits of the SHA-256 of obj's canonical JSON (sorted keys, no spaces)."""
    blob = json.dumps(finite_or_str(obj), sort_keys=True, separators=(",", ":"), default=json_default)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


@dataclass(frozen=True)
class RunConfig:
    """Everything a worker needs for one run; fetched by config hash and cached.

    morphology: the robot's name (for people and run ids, never for building);
    morphology_spec: the morphology's to_dict(), the robot itself (empty for test objectives);
    controller: the controller space's name (None: the morphology's first);
    param_space: ParamSpace.describe() of the space the unit-cube vectors map into;
    trial_config: TrialConfig.to_dict() with the engine, its options and the scene;
    spec_hash, space_hash, trial_config_hash: what a worker must reproduce from the above.
    robust: protocol.robust.RobustSpec.to_dict() of a robust run (K randomised episodes per parameter
    set), empty otherwise (and then left out of to_dict, so a plain run's hash is as before).
    body: robot.codesign.BodySearch.to_dict() of a run that searches the body with the gait (the param space
    then ends with the body's constants), empty otherwise (and left out of to_dict as robust is).
    fit: a model fit's task (worker.fit.task: its recordings and windows; a trial is one candidate's loss),
    empty otherwise (and left out of to_dict as robust is).
    """

    KIND = "run_config"
    run_id: str
    morphology: str
    morphology_spec: dict[str, Any]
    controller: str | None
    param_space: tuple[dict[str, Any], ...]
    trial_config: dict[str, Any]
    objective: str
    seed: int
    spec_hash: str = ""
    space_hash: str = ""
    trial_config_hash: str = ""
    robust: dict[str, Any] = field(default_factory=dict)
    body: dict[str, Any] = field(default_factory=dict)
    fit: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["param_space"] = [dict(p) for p in self.param_space]
        for key in ("robust", "body", "fit"):
            if not d[key]:
                del d[key]
        return d

    def config_hash(self) -> str:
        return json_hash(self.to_dict())

    def space(self) -> ParamSpace:
        return ParamSpace(self.morphology, tuple(
            ParamSpec(p["name"], float(p["low"]), float(p["high"]), str(p.get("unit", "")),
                      str(p.get("doc", "")))
            for p in self.param_space))

    @property
    def is_test_objective(self) -> bool:
        return not self.morphology_spec

    @classmethod
    def from_dict(cls, data: Any) -> RunConfig:
        what = "run config"
        controller = data.get("controller") if isinstance(data, dict) else None
        if controller is not None and not isinstance(controller, str):
            raise MessageError("run config field 'controller' has the wrong type", received=controller,
                               expected="a string or null")
        space = get_field(data, "param_space", list, what)
        if not all(isinstance(p, dict) and {"name", "low", "high"} <= set(p) for p in space):
            raise MessageError("run config has a malformed parameter space", received=space[:2],
                               expected="a list of {name, low, high, unit}")
        hashes = {k: data.get(k, "") for k in ("spec_hash", "space_hash", "trial_config_hash")}
        for k, v in hashes.items():
            if not isinstance(v, str):
                raise MessageError(f"run config field {k!r} has the wrong type", received=v, expected="a string")
        from spinefarm.protocol.errors import ConfigError
        from spinefarm.protocol.robust import RobustSpec

        try:
            robust = RobustSpec.from_dict(data.get("robust")).to_dict() if data.get("robust") else {}
        except ConfigError as exc:
            raise MessageError(f"run config field 'robust' is malformed: {exc}", received=data.get("robust"),
                               expected="{episodes, randomize, statistic}") from exc
        body = data.get("body") or {}
        if not isinstance(body, dict):
            raise MessageError("run config field 'body' has the wrong type", received=type(body).__name__,
                               expected="a mapping (a co-designed run's body search) or nothing")
        fit = data.get("fit") or {}
        if not isinstance(fit, dict) or (fit and not isinstance(fit.get("recordings"), list)):
            raise MessageError("run config field 'fit' is malformed", received=str(fit)[:80],
                               expected="a model fit's task {recordings: [...]} or nothing")
        return cls(get_field(data, "run_id", str, what), get_field(data, "morphology", str, what),
                   get_field(data, "morphology_spec", dict, what), controller, tuple(space),
                   get_field(data, "trial_config", dict, what), get_field(data, "objective", str, what),
                   get_field(data, "seed", int, what), **hashes, robust=robust, body=body,
                   fit=fit)


@dataclass(frozen=True)
class WorkerProblem:
    """A worker cannot serve a run (its spec does not build, a hash does not match, an engine is
    missing): the coordinator stops the run with this reason instead of waiting for ever. It quotes
    a lease the worker holds (trial_id, lease_id), so only a worker the run has handed work can stop it."""

    KIND = "worker_problem"
    worker_id: str
    reason: str
    trial_id: int
    lease_id: int

    def to_dict(self) -> dict[str, Any]:
        return {"worker_id": self.worker_id, "reason": self.reason, "trial_id": self.trial_id,
                "lease_id": self.lease_id}

    @classmethod
    def from_dict(cls, data: Any) -> WorkerProblem:
        what = "worker problem"
        return cls(get_field(data, "worker_id", str, what)[:200], get_field(data, "reason", str, what)[:2000],
                   get_field(data, "trial_id", int, what), get_field(data, "lease_id", int, what))
