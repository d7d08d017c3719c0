"""The arguments of `search` and `coordinator` (and the Zenoh group every service command shares)."""

from __future__ import annotations

import argparse
import os

from spinefarm.cli import checks, engine_auto
from spinefarm.cli.profile_argument import add_profile_argument
from spinefarm.cli.robot_argument import add_robot_argument
from spinefarm.cli.robust_args import add_robust_args
from spinefarm.protocol.settings import DEFAULT_ETA, JUDGE_DT_S


def zenoh_args(p: argparse.ArgumentParser, listen_default: str | None) -> None:
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


def search_args(p: argparse.ArgumentParser, *, local: bool) -> None:
    _run_args(p, local)
    _trial_args(p)
    _service_args(p, local)
    _judge_args(p)
    _ladder_args(p)
    engine_auto.add_arguments(p)
    zenoh_args(p, "tcp/127.0.0.1:<free port>" if local else "tcp/127.0.0.1:7447")


def _run_args(p: argparse.ArgumentParser, local: bool) -> None:
    add_robot_argument(p, omit_with="--resume", more="or the test objective sphere[:N]")
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
    p.add_argument("--seed", type=checks.seed, default=0, help="run seed: fixes every sampled vector by trial number")
    p.add_argument("--objective", default="distance",
                   help="distance (default), speed, cot_distance, pareto (front of speed and COT) or cot:S "
                        "(the least COT among gaits of at least S cm/s, e.g. cot:6.13)")
    p.add_argument("--sampler", default=None,
                   help="cmaes (default: CMA-ES with IPOP restarts), paper (Monte Carlo then hill climbing, "
                        "the paper's), tpe (Optuna TPE) or random; stored with the run")
    p.add_argument("--controller", help="controller parameter space (default: the morphology's)")
    p.add_argument("--sigma", type=float, default=None,
                   help="step in the unit cube: the paper sampler's Gaussian sigma (default 0.005), CMA-ES's initial "
                        "sigma0 (default 0.3)")
    p.add_argument("--top-k", type=int, default=1, help="climb from the k best trials (default 1)")
    p.add_argument("--startup-trials", type=int, help="Monte Carlo trials before climbing (default half)")
    p.add_argument("--enqueue", action="append", default=None, metavar="GAIT.json",
                   help="evaluate this parameter file's set first (a `trial --params` file, e.g. a shipped gait or "
                        "`export --gait`); repeatable, in order; counts in --trials; the samplers go on from it "
                        "(`--sampler paper --startup-trials 0` climbs from the best of them; `--sampler cmaes` centres "
                        "its first distribution on the first of them)")


def _trial_args(p: argparse.ArgumentParser) -> None:
    add_profile_argument(p)
    p.add_argument("--engine", default=None, help="physics engine of every trial: auto (the default of search: "
                   "MuJoCo when a calibration finds it ranks the robot's gaits as Bullet does, else Bullet), "
                   "bullet (the coordinator's default) or mujoco")
    p.add_argument("--engine-option", action="append", default=None, metavar="KEY=VALUE",
                   help="a setting of that engine, e.g. segment_contacts=off; repeatable; stored with the run")
    p.add_argument("--dt", default=None, metavar="S|auto",
                   help="physics step of every trial in seconds (default 0.001), or 'auto' for half the string "
                        "network's stable-step estimate (needed e.g. by tetraspine-hardware); stored with the run")
    checks.add_cpg_step_argument(p)
    p.add_argument("--settle", type=float, default=None, metavar="S",
                   help="let the robot settle this long with the CPG at rest, and score locomotion from the "
                        "settled pose (default 0: from the start, as NTRT)")
    p.add_argument("--scene", default=None,
                   help="flat (default), slope, rough or obstacles with optional ,field=value pairs, e.g. "
                        "'rough,rough_amplitude_cm=3'; stored with the run")


def _service_args(p: argparse.ArgumentParser, local: bool) -> None:
    p.add_argument("--lease", type=float, default=None, metavar="S",
                   help="seconds a worker may hold a trial before it is re-issued (default 60, or 20x duration)")
    p.add_argument("--batch", type=int, default=None,
                   help="trials a local worker pulls per request (default auto)")
    p.add_argument("--api-port", type=int, default=None if local else -1,
                   help="HTTP status API port on localhost (" + ("default 8000 or a free port; " if local
                                                               else "default off; ") + "-1 = off)")
    p.add_argument("--api-host", default="127.0.0.1")
    p.add_argument("--quiet", action="store_true", help="no progress line")
    p.add_argument("--verbose", action="store_true", help="the final report lists the best's parameters")
    if local:
        p.add_argument("--serve", action="store_true",
                       help="keep the dashboard up after the search ends, until Ctrl-C")


def _judge_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--no-verify", action="store_true",
                   help="do not re-simulate new bests at a finer step before they count")
    p.add_argument("--verify-tolerance", type=float, default=None,
                   help="relative distance change at the finer step up to which a best \"holds\" (default: the "
                        "robot's chaos floor, at least 0.01; 0.05 for a robot without a measured one); beyond it "
                        "the best \"moved\" and ranks by its judged distance")
    p.add_argument("--judge-drift", type=float, default=0.2, metavar="REL",
                   help="the judge raises the screen's fidelity for the rest of the run once three judged bests "
                        "(moving 10 cm or more) have a median screen-to-judge distance ratio outside "
                        "[1 - REL, 1 + REL] (default 0.2; up to 10, where a screen that only ranks like the judge, "
                        "at another scale, keeps its speed)")
    p.add_argument("--judge-share", type=float, default=0.25, metavar="FRACTION",
                   help="the most of the workers' time the judge's re-simulations take while the search runs "
                        "(default 0.25; 1: judge every new best at once); the final best is always judged")
    p.add_argument("--opinion", action=argparse.BooleanOptionalAction, default=None,
                   help="run each judged best once more in the other engine at its converged step (Bullet 0.25 ms, "
                        "MuJoCo 1 ms), stored as an \"opinion\" evaluation: the spread between the models "
                        "(default: on when both engines are installed)")
    p.add_argument("--verify-perturb", action="store_true",
                   help="also re-simulate with a jittered start pose and 10 %% more friction")
    g = p.add_argument_group("audit: results re-simulated by another worker")
    g.add_argument("--audit", type=float, default=0.0, metavar="FRACTION",
                   help="re-simulate this fraction of the results, and every new best, on another worker at the "
                        "same fidelity, e.g. 0.02 (default 0: no audit); without --credentials a worker whose "
                        "results disagree gets no more work")
    g.add_argument("--audit-tolerance", type=float, default=0.05, metavar="REL",
                   help="relative distance difference above which an audit disagrees (default 0.05)")


def _ladder_args(p: argparse.ArgumentParser) -> None:
    add_robust_args(p)
    g = p.add_argument_group("multi-fidelity screening")
    g.add_argument("--rungs", metavar="S,S,...", default=None,
                   help="screen every parameter set with a short trial and promote the best 1/eta to each longer "
                        "one (successive halving), e.g. 10,30; the last is the full trial length")
    g.add_argument("--eta", type=int, default=None,
                   help=f"keep the best 1/eta of each rung (default {DEFAULT_ETA} with --rungs; when --engine auto "
                        "adds the rungs, the robot's ladder's, measured: docs/performance.md)")
    g.add_argument("--no-continue", action="store_true",
                   help="simulate every promotion from the start, though the worker that ran its last rung kept "
                        "that rung's end (by default a MuJoCo promotion goes on from it: the same bits, less "
                        "simulated; docs/performance.md)")
    g.add_argument("--verify-engine", default=None,
                   help="re-simulate every new best in this engine before it counts, and report its distance "
                        "(default: bullet whenever the search's --engine is not bullet)")
    g.add_argument("--verify-dt", type=float, default=JUDGE_DT_S, metavar="S",
                   help=f"step of that re-simulation (default {JUDGE_DT_S:g} s, Bullet's converged step)")
