"""Fitting recorded motion, measured.

--identify: recordings made with our own model (tetraspine-ntrt, 2 random gaits of 2 s, every step recorded)
with five constants changed by +-30 %; the fit (spinefarm.worker.fit) starts from the model's own values and
must recover each within 5 %, or say which constants the recordings cannot tell apart and why. Prints one JSON
object: {"constants": {NAME: {"true", "fitted", "rel_error", "identifiable", "why"?}}, ...}.

--windows: how the window length was chosen. On one such recording, per window length: the window error of the
true model (the floor: what restarting from a recorded state with finite-difference velocities costs, growing
with the window as chaos amplifies it) and with each constant 5 % off (the signal); their ratio.

    python bench/fit.py --identify [--engine mujoco] [--evaluations 400] [--restarts 3]
    python bench/fit.py --windows [--engine mujoco]

--ntrt: each spine's model of NTRT's current code (the *-ntrt2026 built-ins, which made the recordings) fitted in
each engine to its NTRT recordings (../shared/ntrt-recordings: the published run and the random draws NTRT ran
to the end, each cut to its first --span seconds): leave-one-out window error of the held-out recording before
and after (worker.fit.loo, the median over the folds), then the fit to all of them and NTRT's published gait
replayed before and after against NTRT's recorded distance in the same time. Only constants with a documented
plausible range are fitted (NTRT_FIT, per engine). Prints
{"spines": {SPINE: {ENGINE: {"ratio_before", "ratio_after", "window_error_before", "window_error_after",
"held_out_improves", "inside_ranges", "folds", "constants", "profile", ...}}}}.

    python bench/fit.py --ntrt [--spines tetraspine-ntrt2026 ...] [--engines mujoco bullet] [--fit NAME,...]
                        [--evaluations N] [--restarts N] [--span 10] [--stride 1] [--replay-duration S] [--jobs N]
                        [--workers N | --connect ENDPOINT]   # the losses on the project's workers over Zenoh

--ntrt --scan NAME=V1,V2,... (or xF: F times the model's own value, each string or rod tag's): no fit (for a budget
a leave-one-out fit exceeds): per spine and engine the window
error of each recording at these values of one constant, and each recording's gait replayed against NTRT's
distance in the same time ({"spines": {SPINE: {ENGINE: {"window_error_cm": {V: {RECORDING: e, "all": e}},
"replay_ratio": {RECORDING: r}}}}}).

--ntrt --terms [--early 1]: no fit; at the model's own constants, every window's error split into its terms
(horizontal and vertical position, rotation, tension: worker.fit.terms) and each pose term's share of the squared
error over all windows, the early ones (starting before --early s: the start-up) and the later ones
({"spines": {SPINE: {ENGINE: {"shares", "shares_early", "shares_late", "windows": {RECORDING: [...]}}}}}).

--ntrt --precision [--single-python /opt/pb-single/bin/python] [--jitter-seeds 3]: no fit; Bullet at NTRT's own
constants, built in single precision (as NTRT's Bullet 2.81/2.82, btScalar = float; docs/fitting.md gives the
build) against the installed double-precision pybullet, side by side in one run: each build measured in its own
interpreter (--measure, one child process per build; --jobs of them at a time), and the chaos floor, the double
build with every segment's start position jittered by 1e-6 cm (seeds 1..N). Per spine and build: the window error
(RMS over every window of its pose error, cm), its terms' shares (as --terms) and NTRT's published gait replayed
against NTRT's recorded distance (its whole length, or --replay-duration; --no-replay: none)
({"builds": {BUILD: {"pybullet", "precision"}}, "spines": {SPINE: {BUILD: {"window_error_cm", "shares",
"replay_ratio", ...}}}}; BUILD "single", "double", "jitter-S").

--ntrt --measure [--engine-option KEY=VALUE ...] [--jitter-seed S]: one build's part of --precision, in this
interpreter, under Bullet engine options (e.g. constraint_solver=mlcp_dantzig, NTRT's current solver; docs/fitting.md).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

# the model's values (tetraspine-ntrt) changed by +-30 %
CHANGED = {"ground_friction": 1.3, "rod_friction": 0.7, "string_stiffness_n_per_m": 1.3,
           "string_damping_n_s_per_m": 0.7, "rod_density_kg_per_cm3": 0.7}


def identify_bench(args: argparse.Namespace) -> dict:
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.robot.profile import current_value
    from spinefarm.worker.fit.identify import identify

    morph = load_morphology(args.robot)
    true = {n: current_value(morph, n, args.engine, {}) * f for n, f in CHANGED.items()}
    t0 = time.time()
    out = identify(morph, args.engine, true, seeds=args.seeds, duration_s=args.duration, window_s=args.window,
                   restarts=args.restarts, evaluations=args.evaluations)
    return {**out, "wall_s": time.time() - t0,
            "command": "python bench/fit.py --identify " + " ".join(sys.argv[2:])}


def windows_bench(args: argparse.Namespace) -> dict:
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.robot.profile import current_value
    from spinefarm.robot.trial_config import TrialConfig
    from spinefarm.worker.fit.fitting import with_values
    from spinefarm.worker.fit.identify import record
    from spinefarm.worker.fit.loss import prepare, window_error_cm

    morph = load_morphology(args.robot)
    true = {n: current_value(morph, n, args.engine, {}) * f for n, f in CHANGED.items()}
    cfg = with_values(TrialConfig(engine=args.engine), true)
    rec = record(morph, cfg, args.seeds[0], args.duration)
    rows = {}
    for window_s in (0.05, 0.1, 0.2, 0.4, 0.8):
        p = prepare("r", rec, window_s, window_s)
        floor = window_error_cm(morph, cfg, [p])
        signal = {n: window_error_cm(morph, with_values(cfg, {n: v * 1.05}), [p]) for n, v in true.items()}
        rows[str(window_s)] = {"windows": len(p.windows), "floor_cm": floor, "off_by_5pct_cm": signal,
                               "signal_to_floor": {n: v / floor for n, v in signal.items()}}
    return {"robot": morph.name, "engine": args.engine, "seed": args.seeds[0], "duration_s": args.duration,
            "window_s": rows, "command": "python bench/fit.py --windows " + " ".join(sys.argv[2:])}


NTRT_FOLDERS = {"tetraspine-ntrt2026": "TetraSpine", "tetrahedral-complex-ntrt2026": "TetrahedralComplex",
                "octahedral-complex-ntrt2026": "OctahedralComplex", "ribbed-ntrt2026": "Ribbed"}
# only constants with a documented plausible range (docs/fitting.md) that NTRT's recordings do not pin already:
# the ground's friction, the engine's contact and the strings' damping (masses, stiffness and the motors are
# NTRT's own numbers in the *-ntrt2026 models, read from its recordings' model-meta.txt)
NTRT_FIT = {"mujoco": "ground_friction,string_damping_n_s_per_m,mujoco.solref_time_s,mujoco.solref_damping_ratio",
            "bullet": "ground_friction,string_damping_n_s_per_m,bullet.erp"}


def ntrt_bench(args: argparse.Namespace) -> dict:
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.robot.trial_config import TrialConfig
    from spinefarm.worker.fit.fitting import fit_constants
    from spinefarm.worker.fit.loo import leave_one_out
    from spinefarm.worker.fit.search import parse_fit

    out: dict = {"spines": {}, "command": "python bench/fit.py --ntrt " + " ".join(sys.argv[2:])}
    for spine in args.spines:
        morph = load_morphology(spine)
        folder = Path(args.recordings) / NTRT_FOLDERS[spine]
        recs = ntrt_recordings(folder, args.window, args.stride, args.span)
        out["spines"][spine] = {}
        for engine in args.engines:
            t0 = time.time()
            cfg, bounds = TrialConfig(engine=engine), parse_fit(args.fit or NTRT_FIT[engine])
            jobs = _where(args, bounds)
            loo = leave_one_out(morph, cfg, recs, bounds, args.restarts, args.evaluations, jobs=jobs)
            fitted = fit_constants(morph, cfg, recs, [], bounds, args.restarts, args.evaluations, jobs=jobs)
            before, after = (_replay_ratio(morph, engine, profile, folder / "published", args.replay_duration)
                             for profile in ({}, fitted["profile"]))
            inside = not any(c["at_bound"] for c in fitted["constants"].values())
            out["spines"][spine][engine] = {
                "ratio_before": before, "ratio_after": after,
                "window_error_before": loo["window_error_before"], "window_error_after": loo["window_error_after"],
                "folds": loo["folds"], "recordings": [p.name for p in recs],
                "held_out_improves": loo["window_error_after"] < loo["window_error_before"],
                "inside_ranges": inside, "profile": fitted["profile"], "constants": fitted["constants"],
                "wall_s": time.time() - t0}
    return out


def _where(args: argparse.Namespace, bounds: list) -> object:
    """Where the losses are computed: --jobs processes here, or with --workers / --connect the project's workers
    over Zenoh (the same bits; spinefarm fit's own options)."""
    from spinefarm.cli.fit_workers import losses_maker

    return losses_maker(argparse.Namespace(workers=args.workers, connect=args.connect, listen=None, jobs=args.jobs),
                        bounds) or args.jobs


def scan_bench(args: argparse.Namespace) -> dict:
    """--ntrt --scan NAME=V1,V2,...: where a full leave-one-out fit does not fit the machine's budget, the window
    error of every recording at a few values of one constant (the model's own among them: is there anything for
    a fit to gain, and in which direction), and each recording's gait replayed against NTRT's distance."""
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.robot.profile import check_constants
    from spinefarm.robot.trial_config import TrialConfig
    from spinefarm.worker.fit.loss import window_error_cm

    name, _, values = args.scan.partition("=")
    out: dict = {"spines": {}, "command": "python bench/fit.py --ntrt " + " ".join(sys.argv[2:])}
    for spine in args.spines:
        morph, folder = load_morphology(spine), Path(args.recordings) / NTRT_FOLDERS[spine]
        recs = ntrt_recordings(folder, args.window, args.stride, args.span)
        out["spines"][spine] = {}
        for engine in args.engines:
            t0, rows = time.time(), {}
            for v in values.split(","):
                cfg = TrialConfig(engine=engine, profile=check_constants(_scan_values(morph, engine, name, v)))
                per = {p.name: window_error_cm(morph, cfg, [p]) for p in recs}
                rows[v] = {**per, "all": window_error_cm(morph, cfg, recs)}
                print(json.dumps({spine: {engine: {name: {v: rows[v]}}}}), file=sys.stderr, flush=True)
            ratios = {} if args.no_replay else {p.name: _replay_ratio(morph, engine, {}, folder / p.name, None)
                                                for p in recs}
            out["spines"][spine][engine] = {"constant": name, "window_error_cm": rows, "replay_ratio": ratios,
                                            "windows": {p.name: len(p.windows) for p in recs},
                                            "wall_s": time.time() - t0}
    return out


def _scan_values(morph: object, engine: str, name: str, value: str) -> dict[str, float]:
    """A scan's profile: NAME=V sets V; NAME=xF multiplies the model's own value by F (a material's: each tag's
    own, so a spine whose strings differ by tag keeps their ratios)."""
    from spinefarm.robot.profile import MATERIALS, constant, current_value

    if not value.startswith("x"):
        return {name: float(value)}
    c, tag = constant(name)
    if c.where not in MATERIALS or tag is not None:
        return {name: current_value(morph, name, engine, {}) * float(value[1:])}
    tags = morph.to_dict()["structure"][MATERIALS[c.where]]
    return {f"{name}.{t}": current_value(morph, f"{name}.{t}", engine, {}) * float(value[1:]) for t in tags}


def terms_bench(args: argparse.Namespace) -> dict:
    """--ntrt --terms: at the model's own constants, each recording's window error split into its terms per window
    (worker.fit.terms), and each term's share over all windows of the spine: which term dominates, and when."""
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.robot.trial_config import TrialConfig
    from spinefarm.worker.fit.terms import term_shares, window_terms

    out: dict = {"spines": {}, "command": "python bench/fit.py --ntrt " + " ".join(sys.argv[2:])}
    for spine in args.spines:
        morph = load_morphology(spine)
        recs = ntrt_recordings(Path(args.recordings) / NTRT_FOLDERS[spine], args.window, args.stride, args.span)
        out["spines"][spine] = {}
        for engine in args.engines:
            per = {p.name: window_terms(morph, TrialConfig(engine=engine), p) for p in recs}
            rows = [r for v in per.values() for r in v]
            early = [r for r in rows if r["start_s"] < args.early]
            late = [r for r in rows if r["start_s"] >= args.early]
            out["spines"][spine][engine] = {"shares": term_shares(rows), "shares_early": term_shares(early),
                                            "shares_late": term_shares(late), "windows": per}
    return out


def precision_bench(args: argparse.Namespace) -> dict:
    """--ntrt --precision: each build of pybullet measured by --measure in its own interpreter (a process holds one
    pybullet), --jobs of them at a time: the single-precision build, the installed double one, and the double one
    with a jittered start (seeds 1..--jitter-seeds: the chaos floor)."""
    import os
    import subprocess

    runs = {"single": (args.single_python, 0), "double": (sys.executable, 0),
            **{f"jitter-{s}": (sys.executable, s) for s in range(1, args.jitter_seeds + 1)}}
    same = ["--spines", *args.spines, "--recordings", args.recordings, "--span", str(args.span), "--stride",
            str(args.stride), "--window", str(args.window), "--early", str(args.early)]
    same += ["--no-replay"] if args.no_replay else []
    same += [f"--engine-option={o}" for o in args.engine_option]
    same += [] if args.replay_duration is None else ["--replay-duration", str(args.replay_duration)]
    t0, load, done = time.time(), os.getloadavg(), {}
    pending = list(runs.items())
    while pending:
        batch, pending = pending[:args.jobs], pending[args.jobs:]
        procs = {name: subprocess.Popen([py, __file__, "--ntrt", "--measure", "--jitter-seed", str(seed), *same],
                                        stdout=subprocess.PIPE, text=True) for name, (py, seed) in batch}
        for name, proc in procs.items():
            text, _ = proc.communicate()
            if proc.returncode:
                raise SystemExit(f"--measure for the {name} build failed (exit {proc.returncode})")
            # pybullet prints its build time on stdout: the report is the JSON line
            done[name] = json.loads(next(line for line in text.splitlines() if line.startswith("{")))
    keys = ("pybullet", "precision", "jitter_seed", "wall_s")
    return {"builds": {n: {k: r[k] for k in keys} for n, r in done.items()},
            "spines": {sp: {n: r["spines"][sp] for n, r in done.items()} for sp in args.spines},
            "wall_s": time.time() - t0, "load_before": load, "load_after": os.getloadavg(),
            "command": "python bench/fit.py --ntrt " + " ".join(sys.argv[2:])}


def measure_bench(args: argparse.Namespace) -> dict:
    """--ntrt --measure (one build, this interpreter's pybullet): Bullet at NTRT's own constants (and any
    --engine-option), per spine the window error, its terms' shares and NTRT's published gait replayed;
    --jitter-seed S > 0 jitters every segment's start position by JITTER_CM (the windows' start states, the
    replay's start pose), seeded by S."""
    from spinefarm.cli.sim_commands import parse_engine_options
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.robot.trial_config import TrialConfig
    from spinefarm.worker.fit.terms import term_shares, window_terms

    t0 = time.time()
    options = parse_engine_options(args.engine_option)
    cfg = TrialConfig(engine="bullet", engine_options=options)
    out: dict = {"pybullet": _pybullet_file(), "precision": bullet_precision(), "jitter_seed": args.jitter_seed,
                 "engine_options": options, "spines": {}, "command": "python bench/fit.py " + " ".join(sys.argv[1:])}
    for spine in args.spines:
        morph, folder = load_morphology(spine), Path(args.recordings) / NTRT_FOLDERS[spine]
        recs = [_jittered(p, args.jitter_seed) for p in ntrt_recordings(folder, args.window, args.stride, args.span)]
        rows = [r for p in recs for r in window_terms(morph, cfg, p)]
        pose_sq = [r["horizontal_cm"] ** 2 + r["vertical_cm"] ** 2 + r["rotation_cm"] ** 2 for r in rows]
        late = [r for r in rows if r["start_s"] >= args.early]
        ratio = None if args.no_replay else _replay_ratio(morph, "bullet", {}, folder / "published",
                                                          args.replay_duration, args.jitter_seed, options)
        out["spines"][spine] = {"window_error_cm": float(np.sqrt(np.mean(pose_sq))), "shares": term_shares(rows),
                                "shares_late": term_shares(late), "windows": len(rows), "replay_ratio": ratio}
    out["wall_s"] = time.time() - t0
    return out


JITTER_CM = 1e-6  # as replay_spread's: perturbations this small already spread a chaotic run


def _jittered(p: object, seed: int) -> object:
    """The recording with every segment's recorded track shifted by a seeded Gaussian JITTER_CM (one offset per
    segment, so velocities are unchanged): the windows start from jittered states and are still checked against
    the recorded poses (p.poses). Seed 0: unchanged."""
    import dataclasses

    if not seed:
        return p
    nb = p.rec.position_m.shape[1]
    shift_m = np.random.default_rng(seed).normal(0.0, JITTER_CM / 100.0, (1, nb, 3))
    return dataclasses.replace(p, rec=dataclasses.replace(p.rec, position_m=p.rec.position_m + shift_m))


def bullet_precision() -> str:
    """"single" or "double": whether this pybullet's btScalar keeps 1 + 2^-40 (a double does, a float does not)."""
    import pybullet as pb

    c = pb.connect(pb.DIRECT)
    try:
        body = pb.createMultiBody(1.0, pb.createCollisionShape(pb.GEOM_SPHERE, radius=1.0, physicsClientId=c),
                                  basePosition=[1.0 + 2.0**-40, 0.0, 0.0], physicsClientId=c)
        x = pb.getBasePositionAndOrientation(body, physicsClientId=c)[0][0]
    finally:
        pb.disconnect(c)
    return "double" if x != 1.0 else "single"


def _pybullet_file() -> str:
    import pybullet as pb

    return str(pb.__file__)


def ntrt_recordings(folder: Path, window_s: float, stride_s: float, span_s: float) -> list:
    """The published run and the random draws NTRT ran to the end, each cut to its first span_s seconds (the
    published run is 30-60 s, the draws 10 s: cut, no recording outweighs the others in the loss)."""
    from spinefarm.worker.fit.loss import prepare
    from spinefarm.worker.fit.readers import read_recording

    draws = [folder / "published", *sorted(folder.glob("random-*"))]
    return [prepare(d.name, _first(read_recording(d), span_s), window_s, stride_s, 0.0) for d in draws if _full(d)]


def _first(rec: object, span_s: float) -> object:
    """The recording's rows up to span_s after its start."""
    import dataclasses

    n = int(np.searchsorted(rec.time_s, rec.time_s[0] + span_s + 1e-9))
    cut = {f: getattr(rec, f)[:n] for f in ("time_s", "position_m", "quat_wxyz", "string_length_m",
                                            "rest_length_m", "tension_n") if getattr(rec, f) is not None}
    return dataclasses.replace(rec, **cut)


def _replay_ratio(morph: object, engine: str, profile: dict, published: Path, duration_s: float | None,
                  jitter_seed: int = 0, options: dict | None = None) -> float:
    """NTRT's published gait replayed on our model: its scored segment's distance over NTRT's recorded one in the
    same time (the published recording's, at duration_s or its end); jitter_seed > 0: the start pose jittered by
    JITTER_CM, seeded; options: engine options over the replay's own."""
    from spinefarm.worker.fit.readers import read_recording
    from spinefarm.worker.fit.state import planar_distance_cm
    from spinefarm.worker.tools.replay import replay

    rec = read_recording(published)
    seg = json.loads((published / "run-info.json").read_text())["scoring_segment"]
    end = len(rec.time_s) - 1 if duration_s is None else int(np.searchsorted(rec.time_s, duration_s - 1e-9))
    ntrt_cm = planar_distance_cm(rec.position_m[0, seg] * 100, rec.position_m[end, seg] * 100)
    ours = replay(published, morph, engine=engine, duration_s=float(rec.time_s[end]), profile=profile,
                  seed=jitter_seed, pose_jitter_cm=JITTER_CM if jitter_seed else 0.0, engine_options=options)
    return ours.result.ntrt_distance_cm / ntrt_cm


def _full(folder: Path) -> bool:
    """A draw that ran its whole trial (NTRT aborted some: they have no score, run-info.json says so)."""
    info = json.loads((folder / "run-info.json").read_text())
    return not any(r.get("aborted") for r in info.get("runs", {}).values())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--identify", action="store_true", help="recover known constants from our own recordings")
    ap.add_argument("--windows", action="store_true", help="window error floor and signal per window length")
    ap.add_argument("--ntrt", action="store_true", help="the built-in spines fitted to NTRT's recordings")
    ap.add_argument("--spines", nargs="+", default=list(NTRT_FOLDERS))
    ap.add_argument("--engines", nargs="+", default=["mujoco", "bullet"])
    ap.add_argument("--recordings", default="/work/shared/ntrt-recordings", help="NTRT's recordings folder")
    ap.add_argument("--fit", default=None, help="with --ntrt: NAME[=LO:HI],... (default per engine: NTRT_FIT)")
    ap.add_argument("--scan", default=None, metavar="NAME=V1,V2,...",
                    help="with --ntrt: no fit; the window error at these values of one constant, and the replays")
    ap.add_argument("--no-replay", action="store_true", help="with --scan, --precision: the window errors only")
    ap.add_argument("--terms", action="store_true", help="with --ntrt: the window error's terms per window")
    ap.add_argument("--precision", action="store_true",
                    help="with --ntrt: Bullet single against double precision and the chaos floor (no fit)")
    ap.add_argument("--single-python", default="/opt/pb-single/bin/python",
                    help="with --precision: the interpreter whose pybullet is built in single precision")
    ap.add_argument("--jitter-seeds", type=int, default=3, help="with --precision: runs of the chaos floor")
    ap.add_argument("--measure", action="store_true",
                    help="with --ntrt: this interpreter's Bullet alone at NTRT's constants (no fit)")
    ap.add_argument("--jitter-seed", type=int, default=0, help="with --measure: jitter the start by 1e-6 cm")
    ap.add_argument("--engine-option", action="append", default=[], metavar="KEY=VALUE",
                    help="with --measure, --precision: a Bullet engine option (JSON value)")
    ap.add_argument("--early", type=float, default=1.0, help="with --terms: windows starting before this are early")
    ap.add_argument("--span", type=float, default=10.0, help="with --ntrt: seconds of each recording fitted")
    ap.add_argument("--stride", type=float, default=1.0)
    ap.add_argument("--replay-duration", type=float, default=None)
    ap.add_argument("--robot", default="tetraspine-ntrt")
    ap.add_argument("--engine", default="mujoco")
    ap.add_argument("--seeds", type=int, nargs="+", default=[3, 5])
    ap.add_argument("--duration", type=float, default=2.0)
    ap.add_argument("--window", type=float, default=0.2)
    ap.add_argument("--restarts", type=int, default=3)
    ap.add_argument("--evaluations", type=int, default=400)
    ap.add_argument("--jobs", type=int, default=1, help="with --ntrt: processes computing a generation's losses")
    ap.add_argument("--workers", type=int, default=None, help="with --ntrt: N local workers over Zenoh compute them")
    ap.add_argument("--connect", nargs="+", default=None, help="with --ntrt: the workers at this router compute them")
    args = ap.parse_args()
    if args.identify + args.windows + args.ntrt != 1:
        ap.error("say what to measure: --identify, --windows or --ntrt")
    bench = identify_bench if args.identify else windows_bench if args.windows else \
        scan_bench if args.scan else terms_bench if args.terms else precision_bench if args.precision else \
        measure_bench if args.measure else ntrt_bench
    print(json.dumps(bench(args)))


if __name__ == "__main__":
    main()
