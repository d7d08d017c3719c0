"""`spinefarm fit --workers N / --connect ENDPOINT`: the fit's losses computed by the project's workers over Zenoh.

The fit serves its run (worker.fit.remote) on a free loopback port (or --listen), or joins the router at
--connect; --workers N starts N local `spinefarm worker` processes for it (kept at strength as a search keeps
its own, cli.local_workers), and workers anywhere else attach as they attach to a search.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import Any

from spinefarm.cli import checks
from spinefarm.cli.local_workers import LocalWorkers, worker_command
from spinefarm.cli.run_setup import credentials, free_port
from spinefarm.protocol.credentials import is_loopback
from spinefarm.protocol.errors import ConfigError


def add_worker_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="compute the losses on N local worker processes over Zenoh (0: only workers that attach)")
    p.add_argument("--connect", nargs="+", default=None, metavar="ENDPOINT",
                   help="join the Zenoh router at ENDPOINT: its workers compute the losses")
    p.add_argument("--listen", nargs="+", default=None, metavar="ENDPOINT",
                   help="serve the fit's run here (default with --workers: a free loopback port)")
    p.add_argument("--credentials", metavar="FILE",
                   help="user:password lines (as search's): the fit authenticates with the first and, when it "
                        "listens, refuses every session whose credentials are not in the file")


def losses_maker(args: argparse.Namespace, bounds: Sequence[Any]) -> Any:
    """None (the losses in this process, or --jobs processes), or what makes them on workers over Zenoh."""
    if args.workers is None and args.connect is None and args.listen is None:
        return None
    if args.jobs != 1:
        raise ConfigError("--jobs and --workers/--connect/--listen both say where the losses are computed",
                                 received=f"--jobs {args.jobs}", expected="one of them")
    checks.at_least("--workers", args.workers or 0, 0, "local worker processes")
    connect = checks.endpoints("--connect", args.connect) or []
    listen = checks.endpoints("--listen", args.listen) or ([] if connect else [f"tcp/127.0.0.1:{free_port()}"])
    creds = credentials(args)
    if creds is None and any(not is_loopback(e) for e in listen):
        print(f"warning: listening on {', '.join(e for e in listen if not is_loopback(e))} without --credentials: "
              "anyone who reaches it can take and return the fit's work", file=sys.stderr)

    def make(morph: Any, cfg: Any, fitted: Sequence[Any]) -> Any:
        from spinefarm.worker.fit.remote import FitNetwork

        return WorkerLosses(morph, cfg, fitted, bounds, FitNetwork(listen, connect, creds), args.workers or 0,
                            args.credentials)

    return make


class WorkerLosses:
    """A fit's RemoteLosses with its local workers: started with it, checked while a generation waits, stopped
    with it."""

    def __init__(self, morph: Any, cfg: Any, fitted: Sequence[Any], bounds: Sequence[Any], network: Any,
                 n_workers: int, credentials_file: str | None = None) -> None:
        from spinefarm.worker.fit.remote import RemoteLosses

        self.remote = RemoteLosses(morph, cfg, fitted, bounds, network)
        endpoint = (network.listen or network.connect)[0].replace("0.0.0.0", "127.0.0.1")
        print(f"fit run {self.remote.run_id} on {endpoint}: attach workers with `spinefarm worker --connect "
              f"{endpoint} --run {self.remote.run_id}`", file=sys.stderr)
        self.workers = LocalWorkers(worker_command(endpoint, self.remote.run_id, 1, None, credentials_file),
                                    n_workers) \
            if n_workers else None
        if self.workers is not None:
            self.remote.on_wait = self.workers.check

    def __call__(self, candidates: list[dict[str, float]]) -> list[float]:
        return self.remote(candidates)

    def close(self) -> None:
        self.remote.close()
        print("fit losses by worker: " + ", ".join(f"{w} {n}" for w, n in sorted(self.remote.by_worker.items())),
              file=sys.stderr)
        if self.workers is not None:
            self.workers.stop()
