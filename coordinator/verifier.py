"""Re-simulation of every new best before it counts ("no exploited physics").

When a stored result becomes the run's best, the coordinator marks it pending and re-simulates it in
a separate process (spawned, so the coordinator never imports the physics engine) at a finer step,
optionally with a perturbed start pose and friction. The verdict is stored beside the result; a best
that does not hold is excluded from "best" everywhere (samplers, API, the final report), and the next
best is checked in turn.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import signal
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import asdict, dataclass
from typing import Any

from spinefarm.protocol.errors import check_range
from spinefarm.protocol.run import RunConfig

log = logging.getLogger("spinefarm.verifier")

# The judge runs below the workers' priority: on a machine whose cores the local workers fill, a converged
# re-simulation (a 30 s Bullet trial at 0.25 ms is ~25 CPU s) would otherwise take a core from them for as
# long as new bests keep coming. It takes what they leave; a best overtaken while it waits is dropped, and
# once the workers are done the last best is judged at full speed.
JUDGE_NICENESS = 10


@dataclass(frozen=True)
class VerifyPolicy:
    """refine: step divisor; tolerance: allowed relative change of the distance; perturb: also jitter
    the start pose (0.01 cm) and raise friction by 10 %.

    engine: re-simulate in another engine (the judge, e.g. bullet behind a mujoco screen) at dt_s (its
    converged step). Two engines are two models (contacts, friction) whose distances differ by more than
    any step error, so then the judge's distance is what counts and is reported; the best only fails if
    the judge's run fails (diverges)."""

    enabled: bool = True
    refine: int = 4
    tolerance: float = 0.05
    perturb: bool = False
    engine: str | None = None
    dt_s: float = 2.5e-4

    def __post_init__(self) -> None:
        check_range("verify refine", self.refine, 1, 64)
        check_range("verify tolerance", self.tolerance, 0.0, 10.0, low_inclusive=False)
        check_range("verify dt_s", self.dt_s, 1e-6, 0.02)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any] | None) -> VerifyPolicy:
        return cls(**(d or {}))


def _verify_job(morphology: Any, controller: str | None, trial_config: dict[str, Any], params_unit: list[float],
                seed: int, distance_m: float, policy: dict[str, Any], duration_s: float | None = None
                ) -> dict[str, Any]:
    """Runs in the verifier process."""
    import dataclasses

    import numpy as np
    from spinefarm.worker.trial import TrialConfig
    from spinefarm.worker.verify import VerifySettings, verify_in_engine, verify_trial

    cfg = TrialConfig.from_dict(trial_config)
    if duration_s is not None:
        cfg = dataclasses.replace(cfg, duration_s=duration_s)
    settings = VerifySettings(refine=policy["refine"], tolerance=policy["tolerance"], perturb=policy["perturb"])
    if policy.get("engine") and policy["engine"] != cfg.engine:
        v = verify_in_engine(morphology, np.asarray(params_unit), cfg, seed, distance_m, policy["engine"],
                             policy["dt_s"], controller=controller)
    else:
        v = verify_trial(morphology, np.asarray(params_unit), cfg, seed, distance_m, settings, controller=controller)
    return v.to_dict()


def _exit_with_parent(parent_pid: int) -> None:
    """Verifier-process initializer: leave as soon as the coordinator is gone, however it ended
    (SIGKILL included): a reparented process sees another parent id."""
    import os
    import threading
    import time

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(0.5)
        os._exit(0)

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


def _verifier_init(parent_pid: int) -> None:
    """Initializer of the re-simulation process: deaf to Ctrl-C, silent, gone with its coordinator."""
    # Ctrl-C reaches the whole process group: the coordinator decides, the re-simulation must not print
    # (a traceback, or the engine's banner, would land in the user's progress line).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.nice(max(0, JUDGE_NICENESS - os.nice(0)))
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    os.dup2(devnull, 2)  # pybullet's banner goes to stderr; a failed job comes back through its future
    _exit_with_parent(parent_pid)


class Verifier:
    """One background process re-simulating new bests; `collect` hands back finished verdicts."""

    def __init__(self, config: RunConfig, policy: VerifyPolicy) -> None:
        self.config = config
        self.policy = policy
        self._pool: ProcessPoolExecutor | None = None
        self._futures: dict[int, Future] = {}

    @staticmethod
    def applies_to(config: RunConfig) -> bool:
        return bool(config.morphology_spec)  # test objectives have no physics to re-check

    @property
    def pending(self) -> list[int]:
        return list(self._futures)

    def submit(self, trial_id: int, params_unit: list[float], seed: int, distance_m: float,
               duration_s: float | None = None) -> None:
        if trial_id in self._futures:
            return
        if self._pool is None:
            self._pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"),
                                             initializer=_verifier_init, initargs=(os.getpid(),))
        morphology = self.config.morphology_spec or self.config.morphology
        self._futures[trial_id] = self._pool.submit(
            _verify_job, morphology, self.config.controller, self.config.trial_config, params_unit, seed,
            distance_m, self.policy.to_dict(), duration_s)

    def cancel_queued(self) -> list[int]:
        """Cancel checks that have not started yet; their trial ids."""
        out = [tid for tid, fut in list(self._futures.items()) if fut.cancel()]
        for tid in out:
            del self._futures[tid]
        return out

    def stop_all_but(self, keep: int) -> list[int]:
        """Drop every check but keep's, a running one included (its process is ended; the next submit
        starts another). The trial ids whose checks were dropped: keep's own too if it was queued behind a
        running one, so the caller submits it again."""
        stale = [tid for tid in self._futures if tid != keep]
        if any(self._futures[tid].running() for tid in stale):
            dropped = list(self._futures)
            self.close()
            self._futures.clear()
            return dropped
        dropped = [tid for tid in stale if self._futures[tid].cancel()]
        for tid in dropped:
            del self._futures[tid]
        return dropped

    def collect(self, wait_s: float = 0.0) -> list[tuple[int, dict[str, Any]]]:
        """(trial id, verification dict) of every finished job; an error becomes a not-reproduced verdict."""
        from concurrent.futures import FIRST_COMPLETED
        from concurrent.futures import wait as wait_futures

        if wait_s > 0 and self._futures:
            wait_futures(list(self._futures.values()), timeout=wait_s, return_when=FIRST_COMPLETED)
        done = []
        for tid, fut in list(self._futures.items()):
            if not fut.done():
                continue
            del self._futures[tid]
            try:
                done.append((tid, fut.result()))
            except Exception as exc:  # the verifier itself failed: say so, never crash the coordinator
                log.error("verification of trial %d failed: %s", tid, exc)
                done.append((tid, {"holds": False, "verdict": f"not reproduced: verification error: {exc}",
                                   "fine_distance_m": float("nan")}))
        return done

    def close(self) -> None:
        if self._pool is not None:
            # A re-simulation still running is stopped, not waited for (exit would join it).
            for proc in list((getattr(self._pool, "_processes", None) or {}).values()):
                proc.terminate()
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None
