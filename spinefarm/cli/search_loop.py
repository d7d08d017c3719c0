"""`search` and `coordinator`: serve a run over Zenoh until its budget, its judge and its audits are
done, with local workers, the HTTP API and a progress line; every exit stores everything."""

from __future__ import annotations

import argparse
import logging
import os
import socket
import sys
import threading
import time
from contextlib import ExitStack
from pathlib import Path
from typing import Any

from spinefarm.cli.local_workers import LocalWorkers, worker_command
from spinefarm.cli.progress import ProgressLine
from spinefarm.cli.report import describe_best, progress, serve_until_stopped
from spinefarm.cli.run_setup import check_run_args, credentials, free_port, open_run
from spinefarm.cli.stop_signals import stop_on_signals
from spinefarm.protocol.errors import ConfigError
from spinefarm.protocol.states import EvaluationKind

PORT_ATTEMPTS = 5  # `search`'s own coordinator port


def cmd_search(args: argparse.Namespace) -> int:
    if args.workers < 0:
        raise ConfigError("--workers out of range", received=args.workers, expected="0 or more")
    return run_coordinator(args, args.workers, None)


def cmd_coordinator(args: argparse.Namespace) -> int:
    return run_coordinator(args, 0, ["tcp/127.0.0.1:7447"])


def start_api(path: Path, host: str, port: int) -> tuple[Any, threading.Thread, int]:
    import uvicorn

    from spinefarm.api.app import create_app

    server = uvicorn.Server(uvicorn.Config(create_app([path]), host=host, port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, name="api", daemon=True)
    thread.start()
    return server, thread, port


def _api_port(args: argparse.Namespace) -> tuple[int, str]:
    """The API's port (the asked one, else a free one) and a note when the asked one is taken."""
    port = args.api_port if args.api_port is not None else 8000
    try:
        with socket.socket() as s:
            s.bind((args.api_host, port))
        return port, ""
    except OSError:
        try:
            return free_port(args.api_host), f" (port {port} is taken)"
        except OSError as exc:
            raise ConfigError(f"cannot serve the API on {args.api_host}: {exc.strerror or exc}",
                              received=args.api_host, expected="a local address (or --api-port -1)") from exc


def _start_service(args: argparse.Namespace, default_listen: list[str] | None) -> tuple[Any, Any, Path, list[str]]:
    from spinefarm.coordinator.service import CoordinatorService

    check_run_args(args)
    creds = credentials(args)  # a bad credentials file fails before any run file is touched
    core, storage, path = open_run(args)
    # default_listen None: a free loopback port, picked again if another process takes it before Zenoh binds it
    own_port = args.listen is None and not args.connect and default_listen is None
    listen = args.listen if args.listen is not None else ([] if args.connect else default_listen or [])
    attempts = PORT_ATTEMPTS if own_port else 1
    for attempt in range(attempts):
        if own_port:
            listen = [f"tcp/127.0.0.1:{free_port()}"]
        service = CoordinatorService(core, storage, listen=listen, connect=args.connect or (),
                                     zenoh_config_file=args.zenoh_config, status_file_for=path, credentials=creds)
        try:
            service.start()
            return core, service, path, listen
        except ConfigError as exc:
            if attempt + 1 == attempts or "already in use" not in str(exc):
                _abandon(storage, path, new=not args.resume)
                raise
        except BaseException:
            _abandon(storage, path, new=not args.resume)
            raise
    raise AssertionError("unreachable")


def _abandon(storage: Any, path: Path, new: bool) -> None:
    """The run could not be served: a run file made just now (no trial in it) goes, so the same command
    works once the cause is fixed; a resumed one stays as it was."""
    from spinefarm.storage.status import status_path

    storage.close()
    if new:
        path.unlink(missing_ok=True)
        status_path(path).unlink(missing_ok=True)


class SearchSession:
    """One coordinator run on this machine: the service, its local workers and API, the progress line."""

    def __init__(self, args: argparse.Namespace, n_workers: int, default_listen: list[str] | None) -> None:
        logging.basicConfig(level=logging.WARNING, format="%(asctime)s %(name)s %(levelname)s %(message)s")
        self.args, self.n_workers = args, n_workers
        self.core, self.service, self.path, listen = _start_service(args, default_listen)
        self.endpoint = (listen or args.connect)[0].replace("0.0.0.0", "127.0.0.1")
        print(f"run {self.core.run_id}: {self.core.study.budget} trials of {self.core.run_config.morphology}, "
              f"file {self.path}", file=sys.stderr)
        print(f"coordinator on {', '.join(listen or args.connect or [])}", file=sys.stderr)
        self.api: tuple[Any, threading.Thread, int] | None = None
        self.workers: LocalWorkers | None = None
        self.stopped = threading.Event()
        stop_on_signals(self.stopped)  # Ctrl-C or a service manager: stop cleanly, store all
        if n_workers == 0:
            print(f"no local workers: attach some with `spinefarm worker --connect {self.endpoint} "
                  f"--run {self.core.run_id}`", file=sys.stderr)
        self.progress = ProgressLine(self.core.study.budget, quiet=args.quiet)
        self.redirect = ExitStack()
        self.redirect.enter_context(self.progress.logging_redirect())

    def serve(self) -> str | None:
        """Run until the run is done, stopped or failing; the failure, if any."""
        args, core = self.args, self.core
        if args.api_port is None or args.api_port >= 0:
            port, taken = _api_port(args)
            self.api = start_api(self.path, args.api_host, port)
            self.progress.write(f"dashboard on http://{args.api_host}:{port}/{taken}; API docs at /docs")
        self.workers = LocalWorkers(worker_command(self.endpoint, core.run_id, args.batch, args.zenoh_config,
                                                   args.credentials), self.n_workers)
        judging = False
        while not core.done and not self.stopped.wait(0.25):
            failure = core.failure or (None if core.done else self.workers.check())
            if failure:
                return failure
            kinds = core.pending_check_kinds() if core.search_done and not judging else set()
            if kinds:  # only when a judge or an audit is still running: with --no-verify there is none
                judging = True
                what = ("the judge re-simulates the best before it is reported" if EvaluationKind.JUDGE in kinds
                        else "the best runs in the other engine for a second opinion"
                        if kinds == {EvaluationKind.OPINION}
                        else "the last audits run")
                self.progress.write(f"the search is done; {what} (Ctrl-C skips) ...")
            self.progress.update(*progress(core))
        end = time.monotonic() + 5.0
        while core.done and not core.workers_released() and time.monotonic() < end:
            time.sleep(0.05)  # let remote workers hear "done" before the coordinator goes away
        return None

    def close(self) -> None:
        if self.workers is not None:
            self.workers.stop()
        self.service.close()
        # `search --serve` keeps the dashboard over the finished file until Ctrl-C (see serve_after)
        self.keep_api = self.api is not None and getattr(self.args, "serve", False) and not self.stopped.is_set()
        if self.api is not None and not self.keep_api:
            self.api[0].should_exit = True
            self.api[1].join(5)
        self.progress.close(progress(self.core)[3])
        self.redirect.close()

    def exit_code(self, failure: str | None, code: int) -> int:
        core, path = self.core, self.path
        if core.write_failure is not None:
            # The file handle whose writes failed is never closed (HDF5 would retry them and crash);
            # the kernel closes it. Every acknowledged result was synced to the disk before the failure.
            print(f"\nstopped: {core.write_failure}; every acknowledged result is in {path}; free space, make "
                  f"the file system writable or replace the failed disk, then continue with: "
                  f"spinefarm search --resume {path}", file=sys.stderr, flush=True)
            sys.stdout.flush()
            os._exit(1)
        if failure and not core.done:
            print(f"\nerror: {failure}", file=sys.stderr)
            code = 1
        elif core.search_done and not core.done:
            print("stopped before the judge finished; the best is reported unverified (everything else is "
                  f"stored; `spinefarm search --resume {path}` judges it)", file=sys.stderr)
            code = 130 if self.stopped.is_set() or code else code
        elif not core.done:
            print(f"stopped with everything stored; continue with: spinefarm search --resume {path}",
                  file=sys.stderr)
            code = 130
        if self.service.close_warnings:  # e.g. a disk full at the end: every result is stored all the same
            print(f"warning: {'; '.join(self.service.close_warnings)}; every result is stored in {path}",
                  file=sys.stderr)
        print(describe_best(core, path, getattr(self.args, "verbose", False)), flush=True)
        return code

    def serve_after(self) -> None:
        if self.api is not None and getattr(self, "keep_api", False):
            serve_until_stopped(self.api, self.args.api_host, self.stopped)


def run_coordinator(args: argparse.Namespace, n_workers: int, default_listen: list[str] | None) -> int:
    session = SearchSession(args, n_workers, default_listen)
    code, failure = 0, None
    try:  # from here on every exit (a startup error too) stops the workers and releases the file
        failure = session.serve()
    except KeyboardInterrupt:
        code = 130
    finally:
        session.close()
    code = session.exit_code(failure, code)
    session.serve_after()
    return code
