"""What the coordinator knows of each worker beyond its leases: the engines it says it can run, the
environment it reports (python, package versions, CPU model), its audit figures and whether it is
quarantined. Audit figures and quarantines are rebuilt from storage on resume (the `audit` and
`worker_id` columns); engines and environments come with every work request.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

from spinefarm.protocol.states import AuditState
from spinefarm.storage.base import BaseStorage


@dataclass
class Peer:
    engines: tuple[str, ...] | None = None   # None: the worker did not say (it is offered everything)
    environment: dict[str, str] = field(default_factory=dict)
    audits_agree: int = 0
    audits_disagree: int = 0
    quarantined: bool = False


class PeerBook:
    """quarantine: a worker whose audited results disagree gets no more leases (credentials off)."""

    def __init__(self, quarantine: bool) -> None:
        self.quarantine = quarantine
        self.peers: dict[str, Peer] = {}

    def peer(self, worker_id: str) -> Peer:
        return self.peers.setdefault(worker_id, Peer())

    def heard(self, worker_id: str, engines: tuple[str, ...] | None, environment: dict[str, str] | None) -> None:
        p = self.peer(worker_id)
        if engines is not None:
            p.engines = engines
        if environment:
            p.environment = dict(environment)

    def runs(self, worker_id: str, engine: str | None) -> bool:
        """The worker may be given a task in `engine` (None: any engine will do)."""
        p = self.peers.get(worker_id)
        return engine is None or p is None or p.engines is None or engine in p.engines

    def audited(self, worker_id: str, agrees: bool) -> None:
        p = self.peer(worker_id)
        if agrees:
            p.audits_agree += 1
        else:
            p.audits_disagree += 1
            p.quarantined = p.quarantined or self.quarantine

    def is_quarantined(self, worker_id: str) -> bool:
        p = self.peers.get(worker_id)
        return p is not None and p.quarantined

    def rebuild(self, storage: BaseStorage) -> None:
        """Audit figures (and so quarantines) from the stored rows."""
        cols = storage.columns()
        # (state, did the result's worker agree, did the auditor agree); a disputed one blames nobody yet
        outcomes = ((AuditState.AGREES, True, True), (AuditState.DISAGREES, False, True),
                    (AuditState.OVERRULED, True, False))
        for state, worker_ok, auditor_ok in outcomes:
            rows = cols["audit"] == state.stored
            for w in cols["worker_id"][rows].tolist():
                self.audited(w.decode("utf-8", "replace"), worker_ok)
            for w in cols["audit_worker_id"][rows].tolist():
                self.audited(w.decode("utf-8", "replace"), auditor_ok)

    def describe(self, worker_id: str) -> dict[str, Any]:
        p = self.peers.get(worker_id) or Peer()
        return {"engines": None if p.engines is None else list(p.engines), "environment": p.environment,
                "audits_agree": p.audits_agree, "audits_disagree": p.audits_disagree,
                "quarantined": p.quarantined}

    def environments(self) -> list[dict[str, Any]]:
        """Audit figures per distinct environment: a mis-built machine shows as one environment."""
        groups: dict[str, dict[str, Any]] = {}
        for wid, p in sorted(self.peers.items()):
            key = json.dumps(p.environment, sort_keys=True)
            g = groups.setdefault(key, {"environment": p.environment, "workers": [], "audits_agree": 0,
                                        "audits_disagree": 0})
            g["workers"].append(wid)
            g["audits_agree"] += p.audits_agree
            g["audits_disagree"] += p.audits_disagree
        return list(groups.values())
