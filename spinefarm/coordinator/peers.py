"""What the coordinator knows of each worker beyond its leases: the engines it says it can run, the
environment it reports (python, package versions, CPU model), its audit figures and whether it is
quarantined. Audit figures and quarantines are rebuilt from storage on resume (the `audit` and
`worker_id` columns); engines and environments come with every work request.

A worker's identity is the Zenoh session its identity queryable answers from (the service asks, Zenoh names
the replier), not the id string it chooses: two ids in one session are one identity, an audit goes to another
identity and a quarantine takes every id of the identity. Without verification (a core driven in-process) the
id is the identity.
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
    identity: str | None = None   # its verified Zenoh session; None: not known (yet)


SEVERAL = "several:"   # an id answered from several sessions: it checks nobody


class PeerBook:
    """quarantine: a worker whose audited results disagree gets no more leases (credentials off).
    verify_identity: identities come from `identified` (the service's probe), else a worker's id is its identity."""

    def __init__(self, quarantine: bool, verify_identity: bool = False) -> None:
        self.quarantine = quarantine
        self.verify_identity = verify_identity
        self.peers: dict[str, Peer] = {}
        self.quarantined_identities: set[str] = set()

    # --- identity -----------------------------------------------------------------------------------
    def identity(self, worker_id: str) -> str | None:
        if not self.verify_identity:
            return worker_id
        p = self.peers.get(worker_id)
        return None if p is None else p.identity

    def identified(self, worker_id: str, sessions: set[str]) -> list[str]:
        """The Zenoh sessions that answered for `worker_id` (none: it did not answer, so it checks nobody); the
        ids it makes quarantined (its session is)."""
        p = self.peer(worker_id)
        if not sessions:
            p.identity = ""
            return []
        p.identity = next(iter(sessions)) if len(sessions) == 1 else SEVERAL + ",".join(sorted(sessions))
        if p.identity in self.quarantined_identities and not p.quarantined:
            p.quarantined = True
            return [worker_id]
        return []

    def unidentified(self) -> list[str]:
        """Workers heard whose identity is still to be asked (or asked again: one that did not answer)."""
        return [w for w, p in self.peers.items() if not p.identity] if self.verify_identity else []

    def may_check(self, worker_id: str, checked: set[str]) -> bool:
        """May `worker_id` audit (or referee) results of the workers `checked`: its identity is known, single
        and none of theirs."""
        mine = self.identity(worker_id)
        if not mine or mine.startswith(SEVERAL):
            return False
        return mine not in {self.identity(w) for w in checked}

    def same_identity(self, worker_id: str) -> list[str]:
        mine = self.identity(worker_id)
        verified = bool(mine) and not mine.startswith(SEVERAL)
        return [w for w in self.peers if w == worker_id or (verified and self.identity(w) == mine)]

    def same_environment(self, a: str, b: str) -> bool:
        """Both workers said what they run on and it is the same (then the same code gives the same bits)."""
        pa, pb = self.peers.get(a), self.peers.get(b)
        return bool(pa and pb and pa.environment and pa.environment == pb.environment)

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

    def audited(self, worker_id: str, agrees: bool) -> list[str]:
        """Count an audit of `worker_id`; the ids it makes quarantined (every id of its identity)."""
        p = self.peer(worker_id)
        if agrees:
            p.audits_agree += 1
            return []
        p.audits_disagree += 1
        return self.quarantine_identity(worker_id) if self.quarantine else []

    def quarantine_identity(self, worker_id: str) -> list[str]:
        """Quarantine `worker_id` and every id answering from its session; the ids newly quarantined."""
        ident = self.identity(worker_id)
        if ident and not ident.startswith(SEVERAL):
            self.quarantined_identities.add(ident)
        newly = [w for w in self.same_identity(worker_id) if not self.peer(w).quarantined]
        for w in newly:
            self.peer(w).quarantined = True
        return newly

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
        for w in set(cols["worker_id"][cols["audit"] == AuditState.QUARANTINED.stored].tolist()):
            self.peer(w.decode("utf-8", "replace")).quarantined = self.quarantine

    def describe(self, worker_id: str) -> dict[str, Any]:
        p = self.peers.get(worker_id) or Peer()
        return {"engines": None if p.engines is None else list(p.engines), "environment": p.environment,
                "audits_agree": p.audits_agree, "audits_disagree": p.audits_disagree,
                "quarantined": p.quarantined, "session": p.identity}

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
