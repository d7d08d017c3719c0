"""Sub-commands of the distributed search: search, coordinator, worker, api, export (their arguments here;
the search in cli.search_loop, its run in cli.run_setup, export in cli.export_command)."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from spinefarm.cli import checks
from spinefarm.cli.export_command import cmd_export
from spinefarm.cli.run_setup import default_run_id, free_port, robot_name
from spinefarm.cli.search_args import search_args, zenoh_args
from spinefarm.cli.search_loop import cmd_coordinator, cmd_search
from spinefarm.cli.stop_signals import stop_on_signals
from spinefarm.protocol.errors import ConfigError

__all__ = ["default_run_id", "free_port", "register", "robot_name"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("search", help="run a whole search on this machine: coordinator, workers, API",
                       description="Embedded Zenoh on loopback, N local worker processes, the HTTP API on "
                                   "localhost and a progress line; Ctrl-C stops with everything stored.")
    search_args(p, local=True)
    p.set_defaults(func=cmd_search, engine_default="auto")

    p = sub.add_parser("coordinator", help="run only the coordinator (workers connect from elsewhere)")
    search_args(p, local=False)
    p.set_defaults(func=cmd_coordinator)

    p = sub.add_parser("worker", help="run a stateless worker that pulls trials from a coordinator")
    p.add_argument("--run", dest="run_id", help="serve only this run (default: any open run found)")
    p.add_argument("--batch", type=int, default=None,
                   help="trials pulled per request (default auto: about 0.5 s of work, 1 for physics)")
    p.add_argument("--worker-id", help="worker id (default <host>-<pid>-<random>)")
    p.add_argument("--exit-when-done", action="store_true",
                   help="exit once the run's budget is met, or its coordinator has been silent for "
                        "--coordinator-timeout seconds (it ended while this worker was frozen or cut off)")
    p.add_argument("--coordinator-timeout", type=float, default=30.0, metavar="S",
                   help="seconds of silence after which --exit-when-done gives a run up (default 30)")
    p.add_argument("--min-trial-limit", type=float, default=30.0, metavar="S",
                   help="a trial's wall-clock limit is max(S, 8 x its measured cost), 10 S before one is measured; "
                        "past it the trial fails (timeout) and the worker goes on (default 30)")
    p.add_argument("--engines", metavar="NAME,...", default=None,
                   help="engines this worker offers (default: every installed one); tasks in others go to other "
                        "workers")
    zenoh_args(p, None)
    p.set_defaults(func=cmd_worker)

    p = sub.add_parser("api", help="serve run files over HTTP: the dashboard at /, the JSON API (run files "
                                   "read-only, notes kept beside them)")
    p.add_argument("files", nargs="*", metavar="RUN.h5")
    p.add_argument("--runs-dir", metavar="DIR", help="serve every *.h5 in DIR (rescanned)")
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, default=8000)
    p.set_defaults(func=cmd_api)

    p = sub.add_parser("export", help="a run file as CSV or Parquet, its best trials or its Pareto front")
    p.add_argument("file", metavar="RUN.h5")
    p.add_argument("--csv", nargs="?", const="-", metavar="OUT.csv", help="write every trial as CSV "
                   "(to OUT.csv, or stdout)")
    p.add_argument("--parquet", metavar="OUT.parquet", help="write every trial as a Parquet table (the "
                   "DataFrame of spinefarm.load_run, units in its metadata)")
    p.add_argument("--best", type=int, metavar="K", help="print the K best trials")
    p.add_argument("--pareto", nargs="?", const="-", metavar="OUT.csv",
                   help="write the Pareto front of speed and COT as CSV, fastest first (to OUT.csv, or stdout)")
    p.add_argument("--gait", metavar="OUT.json", help="write the best trial as a --params file for "
                   "`spinefarm trial` (named physical values, controller space, scores)")
    p.add_argument("--spec", metavar="OUT.yaml", help="a co-designed run (a spec file with a `search:` block): "
                   "write the best trial's body (or --trial's) as a robot file; with --gait, the gait alone")
    p.add_argument("--trial", type=int, metavar="N", help="with --gait or --spec: this trial instead of the best")
    p.set_defaults(func=cmd_export)


# --- worker, api, export ---------------------------------------------------------------------------
def cmd_worker(args: argparse.Namespace) -> int:
    from spinefarm.worker.service.assignment import parse_engines
    from spinefarm.worker.service.zenoh_worker import WorkerService, WorkerTimings, ZenohAccess

    logging.basicConfig(level=logging.WARNING, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    checks.endpoints("--connect", args.connect)
    checks.endpoints("--listen", args.listen)
    if not args.connect and not args.zenoh_config:
        args.connect = ["tcp/127.0.0.1:7447"]
    access = ZenohAccess(args.connect or (), args.listen or (), args.zenoh_config, args.credentials)
    timings = WorkerTimings(coordinator_timeout_s=args.coordinator_timeout, min_trial_limit_s=args.min_trial_limit)
    service = WorkerService(access, run_id=args.run_id, worker_id=args.worker_id, batch=args.batch,
                            engines=parse_engines(args.engines), exit_when_done=args.exit_when_done, timings=timings)
    stop_on_signals(service.stop)
    return service.run()


KEEP_ALIVE_S = 60


def cmd_api(args: argparse.Namespace) -> int:
    import uvicorn

    from spinefarm.api.app import create_app
    from spinefarm.api.registry import servable

    checks.port("--port", args.port)
    if not args.files and args.runs_dir is None:
        raise ConfigError("nothing to serve", expected="run files (RUN.h5 ...) and/or --runs-dir DIR")
    served, skipped = servable([Path(f) for f in args.files])
    for f, exc in skipped:
        print(f"spinefarm api: skipping {f}: {exc}", file=sys.stderr)
    if not served and args.runs_dir is None:
        raise ConfigError("none of the given run files can be served", received=args.files,
                          expected="spinefarm run files (.h5) written by `spinefarm search`")
    if args.runs_dir is not None and not Path(args.runs_dir).is_dir():
        raise ConfigError("--runs-dir is not a folder", received=args.runs_dir, expected="an existing folder")
    announcement = (f"dashboard on http://{args.host}:{args.port}/ ({len(served)} file(s)"
                    + (f", every *.h5 in {args.runs_dir}" if args.runs_dir else "") + ")")

    class AnnouncingServer(uvicorn.Server):
        # The URL is printed once the server listens and answers Ctrl-C itself: a user (or script) that
        # stops it on that line never lands in the start-up, before its signal handlers exist.
        async def startup(self, sockets: list | None = None) -> None:
            await super().startup(sockets)
            if self.started:
                print(announcement, file=sys.stderr, flush=True)

    # A bounded graceful shutdown: SIGTERM stops the server even while a request is still running. Idle
    # connections are kept 60 s (uvicorn's 5 s made a busy server close a connection its client was reusing:
    # a read error at the client under hundreds of readers, bench/api_load.py).
    AnnouncingServer(uvicorn.Config(create_app(served, args.runs_dir), host=args.host, port=args.port,
                                    log_level="warning", timeout_graceful_shutdown=5,
                                    timeout_keep_alive=KEEP_ALIVE_S)).run()
    return 0


