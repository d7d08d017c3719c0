"""A batch of B worlds through one trial's phases (settle, then locomotion) and its divergence checks.

Engine-neutral: the steps go through worker.trial.loop (control law + engine), the guards and the score through
worker.trial.episode. The worlds move in lockstep; a world that diverges, or that its engine wants to run again
in other settings (BasePhysics.retries), leaves the batch and the others go on, unchanged in every bit.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np

from spinefarm.robot.morphology.structure import NEWTON
from spinefarm.robot.scene import Terrain
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.control.law import ControlLaw
from spinefarm.worker.engines.base import BasePhysics
from spinefarm.worker.sim import strings as sk
from spinefarm.worker.trial import guard, loop, scoring
from spinefarm.worker.trial.continued import RungEnd
from spinefarm.worker.trial.episode import STRETCH_BASE_MIN_CM, check_state
from spinefarm.worker.trial.loop import advance, checked_runner, stepper
from spinefarm.worker.trial.settled import Settled


@dataclass
class Trajectory:
    """Recorded at a chosen rate: time_s (n,), poses (n, n_bodies, 7) cm + quaternion,
    tension_n (n, n_strings), cpg_output_cm_s (n, n_nodes), rest_length_cm (n, n_strings), length_cm
    (n, n_strings) each string's anchor distance at the control law's evaluation."""

    time_s: list[float] = field(default_factory=list)
    poses: list[np.ndarray] = field(default_factory=list)
    tension_n: list[np.ndarray] = field(default_factory=list)
    cpg_output_cm_s: list[np.ndarray] = field(default_factory=list)
    rest_length_cm: list[np.ndarray] = field(default_factory=list)
    length_cm: list[np.ndarray] = field(default_factory=list)

    def arrays(self) -> dict[str, np.ndarray]:
        return {"time_s": np.array(self.time_s), "poses": np.array(self.poses),
                "tension_n": np.array(self.tension_n), "cpg_output_cm_s": np.array(self.cpg_output_cm_s),
                "rest_length_cm": np.array(self.rest_length_cm), "length_cm": np.array(self.length_cm)}

    def add(self, t: float, poses: np.ndarray, law: ControlLaw, world: int) -> None:
        self.time_s.append(t)
        self.poses.append(poses.copy())
        self.tension_n.append(law.tension[world] / NEWTON)
        self.cpg_output_cm_s.append(law.cpg_output_cm_s[world].copy())
        self.rest_length_cm.append(law.state[world, :, sk.S_REST].copy())
        self.length_cm.append(law.state[world, :, sk.S_LPREV].copy())


@dataclass(frozen=True)
class Timing:
    """A trial's step counts: n_settle, n_steps (locomotion), cpg_every, check_every, record_every (None:
    no recording), dt_s; cpg_own_step_s: the CPG at its own step, up to this long, setpoints interpolated
    between updates (worker.control.law; None: every cpg_every steps, held)."""

    n_settle: int
    n_steps: int
    cpg_every: int
    check_every: int
    record_every: int | None
    dt_s: float
    cpg_own_step_s: float | None = None


@dataclass
class WorldLog:
    """One world's measurements: the last sane check (pose, step, work) a diverged trial is scored from, the
    COM path, the pose and work at the end of the settle phase, and why it stopped."""

    last_check: np.ndarray
    last_good: np.ndarray
    com_path: list[np.ndarray]
    last_good_step: int = 0
    last_good_work: float = 0.0
    steps_done: int = 0
    reason: str = ""
    retry: bool = False
    settle_poses: np.ndarray | None = None
    settle_work: float = 0.0
    end_poses: np.ndarray | None = None
    end_work: float = 0.0
    trajectory: Trajectory | None = None


class Batch:
    """Runs B worlds of `engine` under `law` for the phases of `timing`, checking every world against `cfg`'s
    guards (masses (nb,) kg, start_length_cm (n_strings,), terrain for heights)."""

    def __init__(self, engine: BasePhysics, law: ControlLaw, timing: Timing, cfg: TrialConfig, masses: np.ndarray,
                 start_length_cm: np.ndarray, terrain: Terrain) -> None:
        self.engine, self.law, self.timing, self.cfg = engine, law, timing, cfg
        self.masses, self.start_length_cm, self.terrain = masses, start_length_cm, terrain
        poses = engine.read_poses()
        self.worlds = [WorldLog(p[:, :3].copy(), p.copy(), [scoring.robot_com_cm(p, masses)]) for p in poses]
        if timing.record_every:
            for w in self.worlds:
                w.trajectory = Trajectory()
        self.active = np.ones(engine.n_worlds, dtype=bool)
        self.done = 0  # steps since the start, settle included, of every world still running
        self._recorded = self.done  # the index of the step the recorder sees next
        self.run_steps = stepper(engine, law, self._record if timing.record_every else None)
        # one world, not recorded: whole check intervals in one compiled call (loop.run_checked), same bits
        self._checked = None if timing.record_every or engine.n_worlds != 1 else checked_runner(engine, law)
        # the compiled fast path of the guard check (worker.trial.guard); None: the exact check every time
        self._boxes = guard.level_boxes(terrain)
        self._limits = guard.limits(cfg)
        self._base_len = np.maximum(start_length_cm, STRETCH_BASE_MIN_CM).astype(np.float64)
        self._mass_total = float(np.asarray(masses, dtype=float).sum())  # the divisor of scoring.robot_com_cm
        self._com = np.zeros(3)
        self._work_at = np.zeros(1)

    def run(self, settled: Settled | None = None, keep_settled: bool = False, resume: RungEnd | None = None,
            keep_end: bool = False) -> list[WorldLog]:
        """Both phases, or with `settled` (every world's start pose and string tables those of its key,
        worker.trial.settled) locomotion only, every world starting from that settle's end. keep_settled: keep world
        0's settle end in self.settled (if it settled and its engine can snapshot it). resume: world 0 (the only one)
        goes on from a kept trial end of its key (worker.trial.continued), in its locomotion phase; keep_end: keep
        world 0's end in self.end (if it ran to its end and its engine can snapshot it)."""
        t = self.timing
        phases = ((t.n_settle, 0), (t.n_steps, t.cpg_every))
        self.settled: Settled | None = None
        self.end: RungEnd | None = None
        if settled is not None or resume is not None:
            if settled is not None:
                self._start_settled(settled)
            phases = phases[1:]
        for phase_steps, every in phases:
            self.law.begin_phase(every, t.dt_s, t.cpg_own_step_s)
            start, n = self.done, 0
            if every and resume is not None:  # the locomotion phase from the kept end's step
                start, n = t.n_settle, self._resume(resume) - t.n_settle
            while n < phase_steps and self.active.any():
                whole = (phase_steps - n) // t.check_every * t.check_every
                if whole and self._checked is not None and self._boxes is not None and self.done % t.check_every == 0:
                    n += self._run_checked(whole, start)
                    continue
                k = min(phase_steps - n, t.check_every - self.done % t.check_every)
                running = self.active.copy()
                self._recorded = self.done
                advance(self.engine, self.run_steps, k, self.active, t.check_every)
                if (running != self.active).any():
                    self._dropped(running & ~self.active, start)
                self.done += k
                n += k
                if self.done % t.check_every == 0:
                    self._check()
            if every == 0 and t.n_settle:  # locomotion is scored from here
                poses = self.engine.read_poses()
                for b in np.flatnonzero(self.active):
                    self.worlds[b].settle_poses = poses[b].copy()
                    self.worlds[b].settle_work = self.law.work_internal(b)
                if keep_settled and self.active[0] and 0 not in self.engine.retries:
                    self.settled = Settled(self.engine.snapshot(0), self.law.state[0].copy(),
                                           self.law.work_internal(0), copy.deepcopy(self.worlds[0]), self.done)
        if keep_end and self.active[0] and not self.worlds[0].reason and 0 not in self.engine.retries:
            # before _finish, which writes the scored end into the log: a longer trial goes on from here
            self.end = RungEnd(self.engine.snapshot(0), self.law.snapshot(0), copy.deepcopy(self.worlds[0]), self.done)
        self._finish()
        return self.worlds

    def _resume(self, end: RungEnd) -> int:
        """World 0 takes a kept end (after begin_phase of the phase it was taken in, which fixes the CPG's plan);
        returns the steps since the start it had taken."""
        self.engine.restore(0, end.engine_state)
        self.law.restore(0, end.law_state)
        self.worlds[0] = end.world_copy()
        self.done = end.done
        return end.done

    def _run_checked(self, n_steps: int, phase_start: int) -> int:
        """Up to n_steps (whole check intervals) of world 0 through loop.run_checked, with Batch's bookkeeping
        for what it ran; where it stopped early, what the piecewise path would do there. Returns steps run."""
        every = self.timing.check_every
        w = self.worlds[0]
        rows = np.empty((n_steps // every, 3))
        check = (every, w.last_check, w.last_good, self.masses, self._mass_total, sk.S_LPREV, self._base_len,
                 every * self.timing.dt_s, self._boxes, self._limits, np.empty_like(w.last_good), self._work_at)
        code, ran, checks = self._checked(0, n_steps, check, rows)
        w.com_path.extend(rows[i].copy() for i in range(checks))
        if checks:
            w.last_good_step, w.last_good_work = self.done + checks * every, float(self._work_at[0])
        self.done += ran
        if code == loop.RAN_LAW_FAILED:
            self.active[0] = False
            self._dropped(~self.active, phase_start)
        elif code == loop.RAN_LOOK_FAILED:  # the engine's own look, at the same state, records the retry
            self.engine.steps_ahead(self.active, 0, every)
            if not self.active[0]:
                self._dropped(~self.active, phase_start)
        elif code == loop.RAN_CHECK_UNCLEAR:
            self._check()
        return ran

    def _start_settled(self, settled: Settled) -> None:
        for b in range(self.engine.n_worlds):
            self.engine.restore(b, settled.engine_state)
            self.law.state[b] = settled.string_state
            self.law.work[b, 0] = settled.work
            self.worlds[b] = settled.world_copy()
        self.done = settled.done

    def _record(self, poses: np.ndarray, active: np.ndarray) -> None:
        step = self._recorded
        if step % self.timing.record_every == 0:
            for b in np.flatnonzero(active):
                self.worlds[b].trajectory.add(step * self.timing.dt_s, poses[b], self.law, b)
        self._recorded = step + 1

    def _dropped(self, worlds: np.ndarray, phase_start: int) -> None:
        for b in np.flatnonzero(worlds):
            w = self.worlds[b]
            if b in self.engine.retries:
                w.retry = True
                continue
            w.steps_done = phase_start + int(self.law.steps[b])
            w.reason = f"diverged: non-finite string state at t={w.steps_done * self.timing.dt_s:.3f} s"

    def _check(self) -> None:
        poses = self.engine.read_poses()
        dt_check = self.timing.check_every * self.timing.dt_s
        state = self.law.state
        for b in np.flatnonzero(self.active):
            w = self.worlds[b]
            if self._boxes is not None and guard.check_clear(
                    poses[b], w.last_check, w.last_good, self.masses, self._mass_total, state[b], sk.S_LPREV,
                    self._base_len, dt_check, self._boxes, self._limits, self._com):
                w.com_path.append(self._com.copy())
                w.last_good_step, w.last_good_work = self.done, self.law.work_internal(b)
                continue
            reason = check_state(poses[b], w.last_check, self.masses, state[b], self.start_length_cm, dt_check,
                                 self.cfg, self.terrain)
            w.last_check = poses[b, :, :3].copy()
            if reason:
                w.reason = f"{reason} at t={self.done * self.timing.dt_s:.3f} s"
                w.steps_done = self.done
                self.active[b] = False
                continue
            w.com_path.append(scoring.robot_com_cm(poses[b], self.masses))
            w.last_good, w.last_good_step, w.last_good_work = poses[b].copy(), self.done, self.law.work_internal(b)

    def _finish(self) -> None:
        end = self.engine.read_poses().copy()
        for b, w in enumerate(self.worlds):
            if w.retry:
                continue
            if self.active[b]:
                w.steps_done = self.done
                if not np.all(np.isfinite(end[b])):
                    w.reason = "diverged: non-finite pose"
                elif w.trajectory is not None:
                    w.trajectory.add(self.done * self.timing.dt_s, end[b], self.law, b)
            if w.reason:  # never score an exploded state: what was measured up to the last sane check
                w.end_poses, w.steps_done, w.end_work = w.last_good, w.last_good_step, w.last_good_work
            else:
                w.end_poses, w.end_work = end[b], self.law.work_internal(b)
