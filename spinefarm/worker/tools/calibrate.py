"""Do the two tiers rank this robot's gaits alike? (`spinefarm calibrate`, `search --engine auto`)

Seeded random gaits plus the bests of a short search on the fast tier (a hill climb from the best random
gait) run on both tiers after a settle phase: MuJoCo at its default step (or the one asked for), and the judge
a search would use, Bullet at the judge's step (protocol.settings.JUDGE_DT_S, 0.25 ms; the automatic step
where that one is unstable for the robot), not at Bullet's default 1 ms, whose own distance error is larger
than the tiers' difference.
From their distances: the Spearman rank correlation, how many of MuJoCo's top 10 are among Bullet's top 10,
and the median distance ratio (MuJoCo / Bullet) over the gaits that move at least 1 cm in Bullet; and for
each tier its cost (CPU s per simulated s) and its step error (median relative change of the distance at
half the step, over a few gaits that move). The fast tier passes when rho >= 0.9, the overlap >= 8 of 10
and the ratio is within [0.9, 1.1]; a search then screens on MuJoCo, otherwise it runs on Bullet.

Results are cached as JSON by the spec's hash, the calibration's settings and a digest of the simulating
code and engine versions (cache_dir()): a change of either engine's model calibrates again. The built-ins'
results ship with the package (worker.tools.shipped_calibration), used when the spec's hash and the settings' key
match.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import math
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from spinefarm.protocol.errors import ConfigError, bounded, check_fields, whole
from spinefarm.protocol.run import json_hash
from spinefarm.protocol.settings import JUDGE_DT_S, JUDGE_ENGINE
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.profile import profile_hash
from spinefarm.worker.tools.pool import Progress, run_jobs

RHO_MIN = 0.9
TOP_K = 10
OVERLAP_MIN = 8  # of TOP_K (scaled down when fewer gaits run)
RATIO_RANGE = (0.9, 1.1)
MOVING_M = 0.01
STEP_ERROR_GAITS = 4  # gaits per tier re-run at half the step
SEARCH_SIGMA = 0.1  # the short search's step in the unit cube
# gaits the short search proposes a round, whatever the processes (`jobs`): a round's proposals are drawn from
# the best before it, so a round of `jobs` made the result depend on the machine's processes. 2: what the
# shipped calibrations were made with (bench/ship_calibrations.py --jobs 2), so they are what a run finds
CLIMB_ROUND = 2
TIERS = ("mujoco", JUDGE_ENGINE)  # the screen, and the reference: the judge's engine
STEP_FIELDS = ("dt_s", "auto_dt")


@dataclass(frozen=True)
class CalibrationSettings:
    """gaits: seeded random gaits (seeds 1..gaits); search_trials: a short search on MuJoCo (a Gaussian
    hill climb from the best random gait, seeds after those), whose `bests` best join them; trials of
    duration_s after a settle_s settle; jobs: processes; dt_s / auto_dt: the screen's step (None and False:
    MuJoCo's default step; auto_dt: at most half the robot's stable-step estimate). The reference runs at
    the judge's step whatever these say (reference_step)."""

    gaits: int = whole(40, 3, 100_000)
    search_trials: int = whole(40, 0, 100_000)
    bests: int = whole(10, 0, 100_000)
    duration_s: float = bounded(5.0, 0.0, 3600.0, low_inclusive=False)
    settle_s: float = bounded(1.0, 0.0, 60.0)
    controller: str | None = None
    jobs: int = whole(1, 1, 100_000)
    profile: tuple[tuple[str, float], ...] = ()  # (name, value) pairs of a profile (robot.profile), sorted
    dt_s: float | None = bounded(None, 1e-6, 0.02)
    auto_dt: bool = False

    def __post_init__(self) -> None:
        check_fields(self, "calibration ")
        if self.bests > self.search_trials:
            raise ConfigError("calibration bests exceed the search's trials", received=self.bests,
                              expected=f"at most {self.search_trials}")

    def key(self) -> str:
        """What the result depends on besides the robot (the step only when one is asked for, so the default's
        key is what it was before the step could be): with a profile, its hash (none without, so that
        calibrations from before profiles keep their key). Not `jobs`: the processes run the same trials in the
        same order (the climb proposes CLIMB_ROUND gaits a round whatever their number), so the result does not
        depend on them (tests/worker_tests/test_calibration_jobs.py)."""
        d = dataclasses.asdict(self)
        key = {k: v for k, v in d.items() if k not in ("jobs", "profile") and not (k in STEP_FIELDS and not v)}
        key["reference"] = [JUDGE_ENGINE, JUDGE_DT_S]  # results against Bullet's default step are not reused
        return json_hash({**key, "profile_hash": profile_hash(dict(self.profile))} if self.profile else key)


def ranks(x: np.ndarray) -> np.ndarray:
    """Average ranks (ties share their mean rank)."""
    order = np.argsort(x, kind="mergesort")
    r = np.empty(len(x))
    r[order] = np.arange(len(x), dtype=float)
    for v in np.unique(x):
        tie = x == v
        if tie.sum() > 1:
            r[tie] = r[tie].mean()
    return r


def spearman(a: np.ndarray, b: np.ndarray) -> float:
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3:
        return math.nan
    ra, rb = ranks(a[ok]), ranks(b[ok])
    if ra.std() == 0 or rb.std() == 0:
        return math.nan
    return float(np.corrcoef(ra, rb)[0, 1])


def agreement(bullet: np.ndarray, mujoco: np.ndarray, top: int = TOP_K) -> dict[str, Any]:
    """Spearman rho, top-`top` overlap and the median distance ratio over gaits moving >= MOVING_M in Bullet."""
    ok = np.isfinite(bullet) & np.isfinite(mujoco)
    moving = ok & (np.abs(bullet) >= MOVING_M)
    k = min(top, int(ok.sum()))
    idx = np.flatnonzero(ok)
    top_b = set(idx[np.argsort(-bullet[ok], kind="stable")[:k]])
    top_m = set(idx[np.argsort(-mujoco[ok], kind="stable")[:k]])
    return {"n": int(ok.sum()), "spearman": spearman(bullet, mujoco), "top_overlap": len(top_b & top_m), "top_k": k,
            "n_moving": int(moving.sum()),
            "median_distance_ratio": float(np.median(mujoco[moving] / bullet[moving])) if moving.any() else None,
            "failed": {"bullet": int((~np.isfinite(bullet)).sum()), "mujoco": int((~np.isfinite(mujoco)).sum())}}


def decide(agree: dict[str, Any]) -> tuple[str, str]:
    """("mujoco" or "bullet", why): MuJoCo screens when it ranks and measures as Bullet does."""
    need = math.ceil(OVERLAP_MIN * agree["top_k"] / TOP_K)
    rho, ratio = agree["spearman"], agree["median_distance_ratio"]
    fails = []
    if not (isinstance(rho, float) and rho >= RHO_MIN):
        fails.append(f"rho {rho:.3f} < {RHO_MIN}")
    if agree["top_overlap"] < need:
        fails.append(f"top-{agree['top_k']} overlap {agree['top_overlap']} < {need}")
    if ratio is None or not RATIO_RANGE[0] <= ratio <= RATIO_RANGE[1]:
        shown = "none (no gait moves)" if ratio is None else f"{ratio:.3f}"
        fails.append(f"distance ratio {shown} outside [{RATIO_RANGE[0]}, {RATIO_RANGE[1]}]")
    if fails:
        return "bullet", "the fast tier disagrees: " + "; ".join(fails)
    return "mujoco", (f"the fast tier agrees: rho {rho:.3f} >= {RHO_MIN}, top-{agree['top_k']} overlap "
                      f"{agree['top_overlap']} >= {need}, distance ratio {ratio:.3f} in [{RATIO_RANGE[0]}, "
                      f"{RATIO_RANGE[1]}]")


_CACHE = None  # one SetupCache per process


def reference_step(source: str) -> tuple[float, bool]:
    """(the reference's step in s, whether it is the automatic one): the judge's step, or the automatic
    step for a robot whose string network is unstable at it (where a search's judge would refuse it)."""
    from spinefarm.robot.trial_config import TrialConfig
    from spinefarm.worker.trial.episode import choose_step

    morph = load_morphology(source)
    try:
        return choose_step(morph, TrialConfig(engine=JUDGE_ENGINE, dt_s=JUDGE_DT_S)), False
    except ConfigError:
        return choose_step(morph, TrialConfig(engine=JUDGE_ENGINE, dt_s=JUDGE_DT_S, auto_dt=True)), True


def _trial(job: tuple) -> tuple[float, float]:
    """(distance m or nan, CPU s per simulated s) of one trial."""
    from spinefarm.robot.trial_config import TrialConfig
    from spinefarm.worker.trial.episode import choose_step
    from spinefarm.worker.trial.setup import SetupCache
    from spinefarm.worker.trial.simulation import simulate

    global _CACHE
    _CACHE = _CACHE or SetupCache(8)
    source, unit, seed, engine, dt_scale, settings = job
    morph = load_morphology(source)
    cfg = TrialConfig(duration_s=settings.duration_s, settle_s=settings.settle_s, engine=engine,
                      profile=dict(settings.profile), dt_s=settings.dt_s, auto_dt=settings.auto_dt)
    if dt_scale != 1.0:  # a fraction of the step the trial would take (an automatic one included)
        cfg = dataclasses.replace(cfg, dt_s=choose_step(morph, cfg) * dt_scale, auto_dt=False)
    t0 = time.process_time()
    r = simulate(morph, np.asarray(unit), cfg, seed, controller=settings.controller, setup=_CACHE).result
    return (r.distance_m if r.ok else math.nan), (time.process_time() - t0) / max(r.sim_time_s, 1e-9)


class _Tally:
    """The calibration's trials done so far, for one progress line over all its phases."""

    def __init__(self, total: int, progress: Progress | None) -> None:
        self.total, self.done, self.progress = total, 0, progress
        if progress:
            progress(0, total)

    def run(self, jobs: list[tuple], processes: int) -> list[tuple[float, float]]:
        start = self.done

        def each(done: int, _total: int) -> None:
            self.done = start + done
            if self.progress:
                self.progress(min(self.done, self.total), self.total)

        return run_jobs(_trial, jobs, processes, each)

    def finish(self) -> None:
        if self.progress:
            self.progress(self.total, self.total)


def trials_in(s: CalibrationSettings) -> int:
    """The trials a calibration runs at most: the random gaits and the search on MuJoCo, those judged on
    Bullet, and the step errors' re-runs."""
    return s.gaits + s.search_trials + s.gaits + s.bests + 2 * STEP_ERROR_GAITS


def _step_error(source: str, gaits: list, distances: np.ndarray, engine: str, settings: CalibrationSettings,
                tally: _Tally) -> float | None:
    """Median |d(dt) - d(dt/2)| / |d(dt/2)| over the first STEP_ERROR_GAITS gaits that move."""
    moving = [i for i in np.argsort(-np.abs(np.nan_to_num(distances)))
              if np.isfinite(distances[i]) and abs(distances[i]) >= MOVING_M][:STEP_ERROR_GAITS]
    if not moving:
        return None
    half = tally.run([(source, gaits[i][0], gaits[i][1], engine, 0.5, settings) for i in moving], settings.jobs)
    errs = [abs(distances[i] - h) / abs(h) for i, (h, _) in zip(moving, half, strict=True) if np.isfinite(h) and h]
    return float(np.median(errs)) if errs else None


def _short_search(source: str, gaits: list, screen: list, s: CalibrationSettings, tally: _Tally) -> list:
    """A Gaussian hill climb on MuJoCo (sigma SEARCH_SIGMA in the unit cube, CLIMB_ROUND proposals a round, run
    in `jobs` processes) from the best random gait: [((unit vector, seed), (distance, cost))] of its
    search_trials trials."""
    rng = np.random.default_rng(0)
    distances = np.nan_to_num([d for d, _ in screen], nan=-np.inf)
    best_u, best_d = np.asarray(gaits[int(np.argmax(distances))][0]), float(np.max(distances))
    out: list = []
    seed = len(gaits)
    while len(out) < s.search_trials:
        batch = []
        for _ in range(min(CLIMB_ROUND, s.search_trials - len(out))):
            seed += 1
            batch.append((tuple(np.clip(best_u + rng.normal(0.0, SEARCH_SIGMA, best_u.shape), 0.0, 1.0)), seed))
        results = tally.run([(source, u, k, "mujoco", 1.0, s) for u, k in batch], s.jobs)
        for g, r in zip(batch, results, strict=True):
            out.append((g, r))
            if np.isfinite(r[0]) and r[0] > best_d:
                best_u, best_d = np.asarray(g[0]), r[0]
    return out


def calibrate(source: str, settings: CalibrationSettings, progress: Progress | None = None) -> dict[str, Any]:
    """Run the calibration of a robot (built-in name or spec file) and return its figures and decision;
    `progress(done, total)` after each trial."""
    from spinefarm.worker.trial.simulation import random_unit_params

    t_wall = time.time()
    morph = load_morphology(source)
    s = settings
    ref_dt_s, ref_auto = reference_step(source)
    ref = dataclasses.replace(s, dt_s=ref_dt_s, auto_dt=False)  # the reference's trials: the judge's step
    tally = _Tally(trials_in(s), progress)
    gaits = [(tuple(random_unit_params(morph, seed, s.controller)), seed) for seed in range(1, s.gaits + 1)]
    screen = tally.run([(source, u, seed, "mujoco", 1.0, s) for u, seed in gaits], s.jobs)
    searched = _short_search(source, gaits, screen, s, tally)
    gaits += [g for g, _ in searched]
    screen += [r for _, r in searched]
    found = np.array([d for d, _ in screen[s.gaits:]])
    bests = [s.gaits + int(i) for i in np.argsort(-np.nan_to_num(found, nan=-np.inf), kind="stable")[:s.bests]]
    chosen = list(range(s.gaits)) + bests
    mujoco = np.array([screen[i][0] for i in chosen])
    judged = tally.run([(source, gaits[i][0], gaits[i][1], JUDGE_ENGINE, 1.0, ref) for i in chosen], s.jobs)
    bullet = np.array([d for d, _ in judged])
    agree = agreement(bullet, mujoco)
    engine, why = decide(agree)
    cost = {"mujoco": float(np.median([screen[i][1] for i in chosen])),
            "bullet": float(np.median([c for _, c in judged]))}
    picked = [gaits[i] for i in chosen]
    tiers = {t: {"cpu_s_per_sim_s": cost[t], "dt_s": _step_of(morph, t, ts),
                 "step_error": _step_error(source, picked, d, t, ts, tally)}
             for t, d, ts in (("mujoco", mujoco, s), (JUDGE_ENGINE, bullet, ref))}
    tally.finish()
    return {"robot": morph.name, "source": str(source), "spec_hash": morph.spec_hash(),
            "profile_hash": profile_hash(dict(s.profile)), "key": s.key(),
            "reference": {"engine": JUDGE_ENGINE, "dt_s": ref_dt_s, "judge_dt_s": JUDGE_DT_S, "auto_dt": ref_auto},
            "settings": dataclasses.asdict(s), "n_random": s.gaits, "n_bests": len(bests), **agree,
            "tiers": tiers, "thresholds": {"spearman": RHO_MIN, "top_overlap": f"{OVERLAP_MIN} of {TOP_K}",
                                           "median_distance_ratio": list(RATIO_RANGE)},
            "decision": engine, "reason": why,
            "distance_m": {"mujoco": _finite_list(mujoco), "bullet": _finite_list(bullet)},
            "wall_s": time.time() - t_wall}


def _step_of(morph: Any, engine: str, s: CalibrationSettings) -> float:
    from spinefarm.robot.trial_config import TrialConfig
    from spinefarm.worker.trial.episode import choose_step

    return choose_step(morph, TrialConfig(engine=engine, dt_s=s.dt_s, auto_dt=s.auto_dt))


def _finite_list(x: np.ndarray) -> list[float | None]:
    return [round(float(v), 6) if np.isfinite(v) else None for v in x]


def cache_dir() -> Path:
    """$SPINEFARM_CACHE_DIR, else $XDG_CACHE_HOME/spinefarm, else ~/.cache/spinefarm; calibrations in calibration/."""
    root = os.environ.get("SPINEFARM_CACHE_DIR")
    if not root:
        root = str(Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "spinefarm")
    return Path(root) / "calibration"


# what decides how a trial moves: the model, the control law and both engines' code and versions
SIMULATING_CODE = ("robot", "worker/engines", "worker/sim", "worker/control", "worker/trial/loop.py",
                   "worker/trial/simulation.py")
ENGINE_PACKAGES = ("mujoco", "pybullet", "numpy", "numba")


def code_digest(paths: list[Path], packages: tuple[str, ...] = ()) -> str:
    """A digest of the contents of the .py files under `paths` (files or folders) and the packages' versions."""
    from importlib.metadata import PackageNotFoundError, version

    h = hashlib.sha256()
    for path in paths:
        files = sorted(path.rglob("*.py")) if path.is_dir() else [path]
        for f in files:
            if f.is_file():
                h.update(f.name.encode() + b"\0" + f.read_bytes() + b"\0")
    for name in packages:
        try:
            h.update(f"{name}=={version(name)}".encode())
        except PackageNotFoundError:
            h.update(f"{name} absent".encode())
    return h.hexdigest()[:12]


@functools.lru_cache(maxsize=1)
def simulating_code_digest() -> str:
    root = Path(__file__).resolve().parents[2]  # the installed spinefarm package (or the checkout)
    return code_digest([root / p for p in SIMULATING_CODE], ENGINE_PACKAGES)


def cache_path(source: str, settings: CalibrationSettings) -> Path:
    return cache_dir() / (f"{load_morphology(source).spec_hash()}-{settings.key()}-"
                          f"{simulating_code_digest()}.json")


def calibration(source: str, settings: CalibrationSettings, refresh: bool = False,
                progress: Progress | None = None) -> tuple[dict[str, Any], bool]:
    """(the calibration of this robot under these settings, whether it came from the cache or the shipped
    calibrations; then its "shipped" is True for the latter)."""
    from spinefarm.worker.tools.shipped_calibration import shipped

    if not refresh and (hit := shipped(source, settings)) is not None:
        return {**hit, "shipped": True}, True
    path = cache_path(source, settings)
    if not refresh and path.is_file():
        try:
            return json.loads(path.read_text()), True
        except (OSError, ValueError):
            pass  # a damaged entry is computed again
    result = clean(calibrate(source, settings, progress))
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(result))
        tmp.replace(path)
    except OSError as exc:  # a read-only home in a container: the figures still count, only uncached
        print(f"warning: the calibration is not cached ({exc.strerror or exc}: {path.parent}); set "
              "SPINEFARM_CACHE_DIR to a writable folder to keep it", file=sys.stderr)
    return result, False


def clean(v: Any) -> Any:
    """The same structure with non-finite floats as None (strict JSON)."""
    if isinstance(v, dict):
        return {k: clean(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [clean(x) for x in v]
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v
