"""Sub-commands of the distributed search: search, coordinator, worker, api, export."""

from __future__ import annotations

import argparse
import logging
import os
import re
import secrets
import signal
import socket
import sys
import threading
import time
from contextlib import ExitStack
from pathlib import Path
from typing import Any

from spinefarm.cli import checks
from spinefarm.cli.local_workers import LocalWorkers, worker_command
from spinefarm.cli.progress import ProgressLine
from spinefarm.protocol.errors import ConfigError


def free_port(host: str = "127.0.0.1") -> int:
    with socket.socket() as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def default_run_id(robot_name: str) -> str:
    """<robot name>-<time>-<random>: valid as a command-line value, a Zenoh key chunk and a file name."""
    stem = re.sub(r"[^A-Za-z0-9_.-]", "-", robot_name).lstrip("-_.")[:24] or "run"
    return f"{stem}-{time.strftime('%Y%m%d-%H%M%S')}-{secrets.token_hex(2)}"


def robot_name(morphology: str) -> str:
    """The name a run is known by: the robot's own name (a spec file's `name:`), never its path."""
    from spinefarm.coordinator.problem import is_test_objective

    if is_test_objective(morphology):
        return morphology.replace(":", "-")
    from spinefarm.robot.morphology.registry import load_morphology

    return load_morphology(morphology).name


# --- argument groups -------------------------------------------------------------------------------
def _zenoh_args(p: argparse.ArgumentParser, listen_default: str | None) -> None:
    g = p.add_argument_group("Zenoh transport")
    g.add_argument("--listen", action="append", metavar="ENDPOINT",
                   help=f"endpoint to listen on, e.g. tcp/0.0.0.0:7447 (default {listen_default or 'none'})")
    g.add_argument("--connect", action="append", metavar="ENDPOINT",
                   help="router or coordinator to connect to, e.g. tcp/HOST:7447")
    g.add_argument("--credentials", metavar="FILE",
                   help="access control: user:password lines (Zenoh user/password authentication); this process "
                        "authenticates with the first line and, when it listens, refuses every session whose "
                        "credentials are not in the file")
    g.add_argument("--zenoh-config", metavar="FILE.json5",
                   help="Zenoh JSON5 config passed through (TLS, access control); endpoints above override it")


def _search_args(p: argparse.ArgumentParser, *, local: bool) -> None:
    p.add_argument("morphology", nargs="?", help="built-in morphology (e.g. tetraspine), a spec file "
                   "(my_spine.yaml) or the test objective sphere[:N]; omit with --resume")
    p.add_argument("--trials", type=int, default=None,
                   help="trial budget (default 2000; with --resume: a new, larger budget)")
    if local:
        p.add_argument("--workers", type=int, default=max(1, (os.cpu_count() or 2) - 0),
                       help="local worker processes (default: one per core)")
    p.add_argument("--duration", type=float, metavar="S", help="simulated seconds per trial")
    p.add_argument("--out", metavar="RUN.h5", help="run file (default runs/<run id>.h5)")
    p.add_argument("--resume", metavar="RUN.h5", help="continue the run stored in this file")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    p.add_argument("--run-id", help="run id (default <morphology>-<time>-<random>)")
    p.add_argument("--seed", type=int, default=0, help="run seed: fixes every sampled vector by trial number")
    p.add_argument("--objective", default="distance",
                   help="distance (default), speed, cot_distance or pareto (front of speed and COT)")
    p.add_argument("--sampler", default=None,
                   help="cmaes (default: CMA-ES with IPOP restarts), paper (Monte Carlo then hill climbing, "
                        "the paper's), tpe (Optuna TPE) or random; stored with the run")
    p.add_argument("--controller", help="controller parameter space (default: the morphology's)")
    p.add_argument("--engine", default=None, help="physics engine of every trial: bullet (default) or mujoco")
    p.add_argument("--engine-option", action="append", default=None, metavar="KEY=VALUE",
                   help="a setting of that engine, e.g. segment_contacts=off; repeatable; stored with the run")
    p.add_argument("--dt", default=None, metavar="S|auto",
                   help="physics step of every trial in seconds (default 0.001), or 'auto' for half the string "
                        "network's stable-step estimate (needed e.g. by tetraspine-hardware); stored with the run")
    p.add_argument("--settle", type=float, default=None, metavar="S",
                   help="let the robot settle this long with the CPG at rest, and score locomotion from the "
                        "settled pose (default 0: from the start, as NTRT)")
    p.add_argument("--scene", default=None,
                   help="flat (default), slope, rough or obstacles with optional ,field=value pairs, e.g. "
                        "'rough,rough_amplitude_cm=3'; stored with the run")
    p.add_argument("--sigma", type=float, default=0.005, help="Gaussian step in the unit cube (default 0.005)")
    p.add_argument("--top-k", type=int, default=1, help="climb from the k best trials (default 1)")
    p.add_argument("--startup-trials", type=int, help="Monte Carlo trials before climbing (default half)")
    p.add_argument("--lease", type=float, default=None, metavar="S",
                   help="seconds a worker may hold a trial before it is re-issued (default 60, or 20x duration)")
    p.add_argument("--batch", type=int, default=None,
                   help="trials a local worker pulls per request (default auto)")
    p.add_argument("--api-port", type=int, default=None if local else -1,
                   help="HTTP status API port on localhost (" + ("default 8000 or a free port; " if local
                                                               else "default off; ") + "-1 = off)")
    p.add_argument("--api-host", default="127.0.0.1")
    p.add_argument("--quiet", action="store_true", help="no progress line")
    p.add_argument("--no-verify", action="store_true",
                   help="do not re-simulate new bests at a finer step before they count")
    p.add_argument("--verify-tolerance", type=float, default=0.05,
                   help="relative distance change a re-simulated best may show (default 0.05)")
    p.add_argument("--verify-perturb", action="store_true",
                   help="also re-simulate with a jittered start pose and 10 %% more friction")
    g = p.add_argument_group("multi-fidelity screening")
    g.add_argument("--rungs", metavar="S,S,...", default=None,
                   help="screen every parameter set with a short trial and promote the best 1/eta to each longer "
                        "one (successive halving), e.g. 10,30; the last is the full trial length")
    g.add_argument("--eta", type=int, default=3, help="keep the best 1/eta of each rung (default 3)")
    g.add_argument("--verify-engine", default=None,
                   help="re-simulate every new best in this engine before it counts, and report its distance "
                        "(default: bullet whenever the search's --engine is not bullet)")
    g.add_argument("--verify-dt", type=float, default=2.5e-4, metavar="S",
                   help="step of that re-simulation (default 0.00025 s, Bullet's converged step)")
    _zenoh_args(p, "tcp/127.0.0.1:<free port>" if local else "tcp/127.0.0.1:7447")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("search", help="run a whole search on this machine: coordinator, workers, API",
                       description="Embedded Zenoh on loopback, N local worker processes, the HTTP API on "
                                   "localhost and a progress line; Ctrl-C stops with everything stored.")
    _search_args(p, local=True)
    p.set_defaults(func=cmd_search)

    p = sub.add_parser("coordinator", help="run only the coordinator (workers connect from elsewhere)")
    _search_args(p, local=False)
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
    _zenoh_args(p, None)
    p.set_defaults(func=cmd_worker)

    p = sub.add_parser("api", help="serve run files over HTTP: the dashboard at /, the JSON API (read-only)")
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
    p.add_argument("--trial", type=int, metavar="N", help="with --gait: this trial instead of the best")
    p.set_defaults(func=cmd_export)


# --- coordinator side ------------------------------------------------------------------------------
def _open_run(args: argparse.Namespace) -> tuple[Any, Any, Path]:
    from spinefarm.coordinator.problem import build_run_config
    from spinefarm.coordinator.setup import SearchSettings, new_run, resume_run

    if args.resume:
        if args.morphology or args.out:
            raise ConfigError("--resume continues a stored run", received="a morphology or --out too",
                              expected="only --resume RUN.h5")
        core, storage = resume_run(args.resume, trials_budget=args.trials)
        return core, storage, Path(args.resume)
    if not args.morphology:
        raise ConfigError("no morphology given", expected="a morphology name (e.g. tetraspine) or --resume")
    run_id = args.run_id or default_run_id(robot_name(args.morphology))
    from spinefarm.cli.sim_commands import trial_overrides

    overrides = trial_overrides(args)
    rungs = None
    if args.rungs is not None:
        from spinefarm.coordinator.fidelity import Rungs

        rungs = Rungs.parse(args.rungs, args.eta)
        if args.duration is not None and args.duration != rungs.durations_s[-1]:
            raise ConfigError("--duration and --rungs disagree on the trial length", received=args.duration,
                              expected=f"--rungs ending at the full length ({rungs.durations_s[-1]:g} s) alone")
        args.duration = rungs.durations_s[-1]
    config = build_run_config(run_id, args.morphology, objective=args.objective, seed=args.seed,
                              controller=args.controller, duration_s=args.duration, trial_overrides=overrides)
    _check_step(config)
    lease = args.lease
    if lease is None:
        duration = config.trial_config.get("duration_s") or 0.0
        lease = max(60.0, 20.0 * float(duration))
    from spinefarm.coordinator.verifier import VerifyPolicy

    screen_engine = config.trial_config.get("engine", "bullet")
    judge = args.verify_engine or ("bullet" if screen_engine != "bullet" else None)
    verify = VerifyPolicy(enabled=not args.no_verify, tolerance=args.verify_tolerance, perturb=args.verify_perturb,
                          engine=judge if judge != screen_engine else None, dt_s=args.verify_dt)
    from spinefarm.coordinator.samplers import DEFAULT_SAMPLER

    settings = SearchSettings(trials=2000 if args.trials is None else args.trials,
                              sampler=args.sampler or DEFAULT_SAMPLER, sigma=args.sigma, top_k=args.top_k,
                              startup_trials=args.startup_trials, lease_s=lease, verify=verify, rungs=rungs)
    out = Path(args.out) if args.out else Path("runs") / f"{run_id}.h5"
    core, storage = new_run(config, settings, out, overwrite=args.overwrite)
    return core, storage, out


def _credentials(args: argparse.Namespace) -> Any:
    if not args.credentials:
        return None
    from spinefarm.protocol.credentials import load_credentials

    creds = load_credentials(args.credentials)
    if creds.world_readable:
        print(f"warning: credentials file {args.credentials} is readable by every user (chmod 600 it)",
              file=sys.stderr)
    return creds


def _check_step(config: Any) -> None:
    """Refuse before the run starts a step every trial would refuse (e.g. tetraspine-hardware at 1 ms)."""
    if config.is_test_objective:
        return
    try:
        from spinefarm.robot.morphology.model import Morphology
        from spinefarm.worker.episode import choose_step
        from spinefarm.worker.trial import TrialConfig
    except ImportError:  # a coordinator without the simulator: the workers will say it
        return
    choose_step(Morphology.from_dict(config.morphology_spec), TrialConfig.from_dict(config.trial_config))


def _check_run_args(args: argparse.Namespace) -> None:
    """Everything typed that can be checked before a run file is created."""
    checks.endpoints("--listen", args.listen)
    checks.endpoints("--connect", args.connect)
    checks.port("--api-port", args.api_port, allow_off=True)
    if args.out:
        checks.output_path("--out", args.out, (".h5", ".hdf5"))


def _start_api(path: Path, host: str, port: int) -> tuple[Any, threading.Thread, int]:
    import uvicorn
    from spinefarm.api.app import create_app

    server = uvicorn.Server(uvicorn.Config(create_app([path]), host=host, port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, name="api", daemon=True)
    thread.start()
    return server, thread, port


def _progress(core: Any) -> tuple[int, int, str, str]:
    """(trials done, budget, what follows a progress bar, the whole line for a log)."""
    with core.lock:  # the transport threads write the table concurrently
        st = core.status()
        best = core.study.storage.best(1)
    done = st["trials_complete"] + st["trials_failed"]
    budget = st.get("trials_planned", st["trials_budget"])
    width = 24
    fill = int(width * done / max(budget, 1))
    best_s = f"{best[0].distance_m:.3f} m" if best else "-"
    eta = "-" if st["eta_s"] is None else f"{st['eta_s']:.0f}s"
    text = f"{st['trials_failed']} failed, {st['rate_trials_s']:.1f}/s, best {best_s}"
    return done, budget, text, (f"[{'#' * fill}{'.' * (width - fill)}] {done}/{budget} trials ({st['trials_failed']} "
                                f"failed)  {st['rate_trials_s']:.1f}/s  best {best_s}  ETA {eta}")


def _describe_best(core: Any, path: Path) -> str:
    storage = core.study.storage
    best = storage.best(1)
    if not best:
        return f"no complete trial yet; file {path}"
    b = best[0]
    names = storage.run_meta().param_names
    units = storage.run_meta().param_units
    params = ", ".join(f"{n}={v:.4g}{(' ' + u) if u and u != '1' else ''}"
                       for n, v, u in zip(names, b.params, units, strict=True))
    judge = core.verifier.policy.engine if core.verifier is not None else None
    holds = (f"verified in {judge}: {b.verify_distance_m:.4g} m, {100 * b.verify_distance_m / b.sim_time_s:.4g} "
             f"cm/s (the distance that counts)" if judge else f"holds at a finer step ({b.verify_distance_m:.4g} m)")
    check = {"holds": holds, "pending": "verification pending", "": "not verified"}.get(b.verification,
                                                                                        b.verification)
    engine = f" in {b.engine} at {b.dt_s * 1e3:g} ms" if b.engine else ""
    return (f"best trial {b.trial_id} ({b.phase}, {b.sim_time_s:g} s{engine}): objective {b.objective:.4g}, "
            f"distance {b.distance_m:.4g} m, speed {b.speed_cm_s:.4g} cm/s, work {b.work_j:.4g} J, "
            f"COT {b.cot:.4g}; {check}\n"
            f"  params: {params}\nfile: {path}")


def _run_coordinator(args: argparse.Namespace, n_workers: int, default_listen: list[str]) -> int:
    from spinefarm.coordinator.service import CoordinatorService

    logging.basicConfig(level=logging.WARNING, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    _check_run_args(args)
    credentials = _credentials(args)  # a bad credentials file fails before any run file is touched
    core, storage, path = _open_run(args)
    listen = args.listen if args.listen is not None else ([] if args.connect else default_listen)
    service = CoordinatorService(core, storage, listen=listen, connect=args.connect or (),
                                 zenoh_config_file=args.zenoh_config, status_file_for=path,
                                 credentials=credentials)
    try:
        service.start()
    except BaseException:
        storage.close()
        raise
    print(f"run {core.run_id}: {core.study.budget} trials of {core.run_config.morphology}, file {path}",
          file=sys.stderr)
    print(f"coordinator on {', '.join(listen or args.connect or [])}", file=sys.stderr)
    api = None
    endpoint = (listen or args.connect)[0]
    endpoint = endpoint.replace("0.0.0.0", "127.0.0.1")
    workers: LocalWorkers | None = None
    stopped = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):  # Ctrl-C or a service manager: stop cleanly, store all
        signal.signal(sig, lambda *_: stopped.set())
    if n_workers == 0:
        print(f"no local workers: attach some with `spinefarm worker --connect {endpoint} --run {core.run_id}`",
              file=sys.stderr)
    progress = ProgressLine(core.study.budget, quiet=args.quiet)
    redirect = ExitStack()
    redirect.enter_context(progress.logging_redirect())
    code = 0
    failure: str | None = None
    try:  # from here on every exit (a startup error too) stops the workers and releases the file
        if args.api_port is None or args.api_port >= 0:
            port = args.api_port if args.api_port is not None else 8000
            taken = ""
            try:
                with socket.socket() as s:
                    s.bind((args.api_host, port))
            except OSError:
                try:
                    taken, port = f" (port {port} is taken)", free_port(args.api_host)
                except OSError as exc:
                    raise ConfigError(f"cannot serve the API on {args.api_host}: {exc.strerror or exc}",
                                      received=args.api_host, expected="a local address (or --api-port -1)") from exc
            api = _start_api(path, args.api_host, port)
            progress.write(f"dashboard on http://{args.api_host}:{port}/{taken}; API docs at /docs")
        workers = LocalWorkers(worker_command(endpoint, core.run_id, args.batch, args.zenoh_config,
                                              args.credentials), n_workers)
        while not core.done and not stopped.wait(0.25):
            failure = core.failure or (None if core.done else workers.check())
            if failure:
                break
            progress.update(*_progress(core))
        end = time.monotonic() + 5.0
        while core.done and not core.workers_released() and time.monotonic() < end:
            time.sleep(0.05)  # let remote workers hear "done" before the coordinator goes away
        if core.done and core.verifier is not None and core.verifier.pending:
            progress.update(*_progress(core))
            progress.write("re-simulating the best at a finer step before reporting it (Ctrl-C skips) ...")
            end = time.monotonic() + 600.0
            while not stopped.is_set() and not core.finish_verifications(timeout_s=0.5) and time.monotonic() < end:
                pass
            if core.verifier.pending:
                why = "stopped" if stopped.is_set() else "verification not finished"
                progress.write(f"{why}; the best is reported unverified (everything else is stored)")
                code = 130 if stopped.is_set() else code
    except KeyboardInterrupt:
        code = 130
    finally:
        if workers is not None:
            workers.stop()
        service.close()
        if core.verifier is not None:
            core.verifier.close()
        if api is not None:
            api[0].should_exit = True
            api[1].join(5)
        progress.close(_progress(core)[3])
        redirect.close()
    if core.write_failure is not None:
        # The file handle whose writes failed is never closed (HDF5 would retry them and crash);
        # the kernel closes it. Every acknowledged result was synced to the disk before the failure.
        print(f"\nstopped: {core.write_failure}; every acknowledged result is in {path}; free space, make "
              f"the file system writable or replace the failed disk, then continue with: "
              f"spinefarm search --resume {path}",
              file=sys.stderr, flush=True)
        sys.stdout.flush()
        os._exit(1)
    if failure and not core.done:
        print(f"\nerror: {failure}", file=sys.stderr)
        code = 1
    elif not core.done:
        print(f"stopped with everything stored; continue with: spinefarm search --resume {path}",
              file=sys.stderr)
        code = 130
    print(_describe_best(core, path))
    return code


def cmd_search(args: argparse.Namespace) -> int:
    if args.workers < 0:
        raise ConfigError("--workers out of range", received=args.workers, expected="0 or more")
    return _run_coordinator(args, args.workers, [f"tcp/127.0.0.1:{free_port()}"])


def cmd_coordinator(args: argparse.Namespace) -> int:
    return _run_coordinator(args, 0, ["tcp/127.0.0.1:7447"])


# --- worker, api, export ---------------------------------------------------------------------------
def cmd_worker(args: argparse.Namespace) -> int:
    from spinefarm.worker.service import WorkerService

    logging.basicConfig(level=logging.WARNING, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    checks.endpoints("--connect", args.connect)
    checks.endpoints("--listen", args.listen)
    if not args.connect and not args.zenoh_config:
        args.connect = ["tcp/127.0.0.1:7447"]
    service = WorkerService(connect=args.connect or (), run_id=args.run_id, worker_id=args.worker_id,
                            batch=args.batch, listen=args.listen or (), zenoh_config_file=args.zenoh_config,
                            exit_when_done=args.exit_when_done, coordinator_timeout_s=args.coordinator_timeout,
                            credentials_file=args.credentials)
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: service.stop.set())
    return service.run()


def cmd_api(args: argparse.Namespace) -> int:
    import uvicorn
    from spinefarm.api.app import create_app
    from spinefarm.protocol.errors import StorageError
    from spinefarm.storage.hdf5 import read_meta

    checks.port("--port", args.port)
    if not args.files and args.runs_dir is None:
        raise ConfigError("nothing to serve", expected="run files (RUN.h5 ...) and/or --runs-dir DIR")
    served = []
    for f in args.files:
        try:
            if not Path(f).is_file():
                raise StorageError("no such file", expected="an existing run file")
            read_meta(f)
            served.append(f)
        except StorageError as exc:
            print(f"spinefarm api: skipping {f}: {exc}", file=sys.stderr)
    if not served and args.runs_dir is None:
        raise ConfigError("none of the given run files can be served", received=args.files,
                          expected="spinefarm run files (.h5) written by `spinefarm search`")
    if args.runs_dir is not None and not Path(args.runs_dir).is_dir():
        raise ConfigError("--runs-dir is not a folder", received=args.runs_dir, expected="an existing folder")
    print(f"dashboard on http://{args.host}:{args.port}/ ({len(served)} file(s)"
          + (f", every *.h5 in {args.runs_dir}" if args.runs_dir else "") + ")", file=sys.stderr)
    # A bounded graceful shutdown: SIGTERM stops the server even while a request is still running.
    uvicorn.run(create_app(served, args.runs_dir), host=args.host, port=args.port, log_level="warning",
                timeout_graceful_shutdown=5)
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    from spinefarm.storage.export import best_table, write_csv
    from spinefarm.storage.hdf5 import Hdf5Storage

    if all(v is None for v in (args.csv, args.best, args.pareto, args.parquet, args.gait)):
        raise ConfigError("nothing to export", expected="--csv [OUT.csv], --parquet OUT.parquet, --best K, "
                          "--pareto [OUT.csv] and/or --gait OUT.json")
    if args.csv not in (None, "-"):
        checks.output_path("--csv", args.csv, (".csv",))
    if args.pareto not in (None, "-"):
        checks.output_path("--pareto", args.pareto, (".csv",))
    if args.parquet is not None:
        checks.output_path("--parquet", args.parquet, (".parquet",))
    if args.gait is not None:
        checks.output_path("--gait", args.gait, (".json",))
    checks.at_least("--best", args.best, 1, "K best trials")
    storage = Hdf5Storage.open_read(args.file)
    if args.parquet is not None:
        _write_parquet(args.file, args.parquet)
    if args.csv is not None:
        if args.csv == "-":
            write_csv(storage, sys.stdout)
        else:
            with open(args.csv, "w", newline="") as fh:
                write_csv(storage, fh)
            print(f"wrote {storage.n_trials()} trials to {args.csv}", file=sys.stderr)
    if args.best is not None:
        if args.best < 1:
            raise ConfigError("--best out of range", received=args.best, expected="K >= 1")
        print(best_table(storage, args.best))
    if args.pareto is not None:
        ids = storage.pareto_ids()
        if args.pareto == "-":
            write_csv(storage, sys.stdout, ids)
        else:
            with open(args.pareto, "w", newline="") as fh:
                write_csv(storage, fh, ids)
            print(f"wrote {len(ids)} Pareto-front trials to {args.pareto}", file=sys.stderr)
    if args.gait is not None:
        import json

        from spinefarm.storage.export import gait_params

        Path(args.gait).parent.mkdir(parents=True, exist_ok=True)
        Path(args.gait).write_text(json.dumps(gait_params(storage, args.trial), indent=1) + "\n")
        which = "the best trial" if args.trial is None else f"trial {args.trial}"
        print(f"wrote the parameters of {which} to {args.gait}", file=sys.stderr)
    return 0


def _write_parquet(run_file: str, out: str) -> None:
    try:
        import pyarrow  # noqa: F401
    except ImportError as exc:
        raise ConfigError("--parquet needs pyarrow", received="no pyarrow here",
                          expected="pip install 'spinefarm[data]'") from exc
    from spinefarm import load_run

    df = load_run(run_file)
    df.to_parquet(out)
    print(f"wrote {len(df)} trials to {out}", file=sys.stderr)
