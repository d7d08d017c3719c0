"""Every Zenoh key expression spinefarm uses, spelt in one place.

All run traffic lives under ``spinefarm/run/<run_id>/`` so several runs can share one Zenoh
network; worker liveliness tokens live under ``spinefarm/workers/`` because one worker can
serve any run.
"""

from __future__ import annotations

import re

from spinefarm.protocol.errors import ConfigError

ROOT = "spinefarm"
# A run id is one key-expression chunk: no '/', wildcards or verbatim markers.
_RUN_ID = re.compile(r"^[A-Za-z0-9_.\-]{1,64}$")
# a run id also travels as a command-line value and a file name: it starts with a letter or digit
_RUN_ID_START = re.compile(r"^[A-Za-z0-9]")


def check_run_id(run_id: str) -> str:
    if not isinstance(run_id, str) or not _RUN_ID.match(run_id) or not _RUN_ID_START.match(run_id):
        raise ConfigError("run id is not valid", received=run_id,
                          expected="1-64 characters from A-Z a-z 0-9 _ . -, starting with a letter or digit")
    return run_id


def check_worker_id(worker_id: str) -> str:
    if not isinstance(worker_id, str) or not _RUN_ID.match(worker_id):
        raise ConfigError("worker id is not a valid key chunk", received=worker_id,
                          expected="1-64 characters from A-Z a-z 0-9 _ . -")
    return worker_id


def run_prefix(run_id: str) -> str:
    return f"{ROOT}/run/{check_run_id(run_id)}"


def run_info(run_id: str) -> str:
    """Queryable answering with a RunInfo: lets workers discover runs."""
    return f"{run_prefix(run_id)}/info"


def all_run_infos() -> str:
    """Selector a worker queries to discover every run on the network."""
    return f"{ROOT}/run/*/info"


def work(run_id: str) -> str:
    """Queryable: a WorkRequest in, a WorkGrant (a batch of leased trials) out."""
    return f"{run_prefix(run_id)}/work"


def results(run_id: str) -> str:
    """Queryable: a ResultSubmission in, a ResultAck out (workers resend until acknowledged)."""
    return f"{run_prefix(run_id)}/results"


def problem(run_id: str) -> str:
    """Queryable: a worker that cannot serve the run says why (WorkerProblem)."""
    return f"{run_prefix(run_id)}/problem"


def config(run_id: str, config_hash: str) -> str:
    """Queryable: the RunConfig whose hash is `config_hash`."""
    if not re.fullmatch(r"[0-9a-f]{8,64}", config_hash or ""):
        raise ConfigError("config hash is not hex", received=config_hash, expected="8-64 hex digits")
    return f"{run_prefix(run_id)}/config/{config_hash}"


def worker_token(worker_id: str) -> str:
    """Liveliness token a worker declares while its session is up."""
    return f"{ROOT}/workers/{check_worker_id(worker_id)}"


def all_worker_tokens() -> str:
    return f"{ROOT}/workers/*"


def worker_id_of_token(key: str) -> str | None:
    """Worker id from a liveliness key, or None for a foreign key."""
    prefix = f"{ROOT}/workers/"
    if not key.startswith(prefix):
        return None
    rest = key[len(prefix):]
    return rest if _RUN_ID.match(rest) else None


def worker_identity(worker_id: str) -> str:
    """Queryable a worker declares in its own session: the coordinator asks it and reads the Zenoh session id
    of the reply (set by Zenoh, not by the worker), so two worker ids in one session are one identity."""
    return f"{ROOT}/identity/{check_worker_id(worker_id)}"


def holder_token(run_id: str, holder: str) -> str:
    """Liveliness token of the coordinator holding a run (holder: its start time and session id), so a copy
    of the run's file resumed on the same network sees that the run is held."""
    return f"{run_prefix(run_id)}/holder/{check_worker_id(holder)}"


def all_holder_tokens(run_id: str) -> str:
    return f"{run_prefix(run_id)}/holder/*"


def holder_of_token(key: str) -> str:
    return key.rsplit("/", 1)[-1]
