"""Multiple shooting: many short windows, each simulated from the recorded state at its start.

Every window is one world of one engine batch: its bodies are put at the recorded poses with velocities by
finite differences (one state write per body, the engine's "set_state"), and its strings follow the recorded
rest lengths (the recording's "rest_lengths" drive: no controller, no motor, the string law on the given rest
lengths, so a window needs no controller state from before it). The simulated poses are kept at the recorded
samples inside the window.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from spinefarm.protocol.errors import ConfigError
from spinefarm.robot.engines import engine_spec
from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.morphology.structure import NEWTON
from spinefarm.robot.profile import apply_profile
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.control.law import string_tables
from spinefarm.worker.engines.base import BasePhysics
from spinefarm.worker.fit.recording import Recording, RecordingError
from spinefarm.worker.fit.state import engine_poses, rest_lengths_cm, velocities
from spinefarm.worker.sim import strings as sk
from spinefarm.worker.trial.loop import advance
from spinefarm.worker.trial.setup import TrialSetup


@dataclass(frozen=True)
class Window:
    """start: the recording's row the window starts from; rows: the rows checked inside it (after the start)."""

    start: int
    rows: tuple[int, ...]


def plan_windows(rec: Recording, window_s: float, stride_s: float, skip_s: float = 0.0) -> list[Window]:
    """Windows of window_s starting every stride_s from skip_s on, each checked at every recorded sample in it."""
    t = rec.time_s
    out, t0 = [], t[0] + skip_s
    while t0 + window_s <= t[-1] + 1e-9:
        start = int(np.searchsorted(t, t0 - 1e-9))
        rows = np.flatnonzero((t > t[start] + 1e-9) & (t <= t[start] + window_s + 1e-9))
        if len(rows):
            out.append(Window(start, tuple(int(r) for r in rows)))
        t0 += stride_s
    if not out:
        raise RecordingError(f"{rec.where}too short for one window", received=f"{t[-1] - t[0]:g} s",
                             expected=f"at least {skip_s + window_s:g} s")
    return out


@dataclass
class WindowRun:
    """A simulated window at its checked rows: poses (rows, nb, 7) COM cm + quaternion (x, y, z, w) and the
    strings' spring tensions tension_n (rows, n_strings) N; NaN from where it diverged."""

    poses: np.ndarray
    tension_n: np.ndarray


def driven_strings(morph: Morphology) -> np.ndarray:
    """The robot's controller-driven strings (their tags have control gains), in its string order."""
    return np.array([i for i, s in enumerate(morph.structure.strings) if morph.control.gains(s.tag) is not None],
                    dtype=int)


def run_windows(morph: Morphology, cfg: TrialConfig, rec: Recording, windows: list[Window]) -> list[WindowRun]:
    """Every window simulated from its recorded start state under cfg (its profile applied)."""
    if rec.rest_length_m is None:
        raise RecordingError(f"{rec.where}no rest lengths to drive the strings", received="no rest_length_m",
                             expected="a recording with rest lengths (docs/recordings.md)")
    if not engine_spec(cfg.engine).can("set_state"):
        raise ConfigError("the engine cannot start from a recorded state", received=cfg.engine,
                          expected="an engine with the set_state ability")
    morph = apply_profile(morph, cfg.profile)
    setup = TrialSetup(morph, cfg, None)
    recorded = rec.check_robot(len(setup.bodies), len(morph.structure.strings), morph.name, driven_strings(morph))
    out = _batch(setup, rec, windows, recorded)
    retry = [w for w, o in enumerate(out) if o is None]
    if retry:  # the engine asked for other settings (MuJoCo's contact guard): those windows again, in them
        again = dataclasses.replace(cfg, engine_options={**cfg.engine_options, "segment_contacts": "scene"})
        for w, run in zip(retry, run_windows(morph, again, rec, [windows[w] for w in retry]), strict=True):
            out[w] = run
    return out  # type: ignore[return-value]


class _Shots:
    """The windows' string banks driven by their rest-length tables, and what is kept at the checked steps.
    recorded: the robot's strings the recording's columns are; the others (passive strings a recording may leave
    out) keep the model's own rest length."""

    def __init__(self, setup: TrialSetup, rec: Recording, windows: list[Window], recorded: np.ndarray) -> None:
        dt, t = setup.dt, rec.time_s
        self.recorded = recorded
        self.dt, self.step = dt, 0
        self.n_steps = max(int(round((t[w.rows[-1]] - t[w.start]) / dt)) for w in windows)
        self.check = [{int(round((t[r] - t[w.start]) / dt)): i for i, r in enumerate(w.rows)} for w in windows]
        self.rest = [rest_lengths_cm(rec, t[w.start] + dt * np.arange(self.n_steps)) for w in windows]
        params, state = string_tables(setup.morph, setup.geom.start_length_cm, {})
        params[:, sk.P_MODE] = sk.MODE_FIXED  # the rest lengths are given: no motor, no controller
        g, nb = setup.geom, len(setup.bodies)
        self.banks = [sk.StringBank(nb, g.body_a, g.body_b, g.anchor_a_cm, g.anchor_b_cm, params, state.copy())
                      for _ in windows]
        self.runs = [WindowRun(np.full((len(w.rows), nb, 7), np.nan), np.full((len(w.rows), len(recorded)), np.nan))
                     for w in windows]
        self.force = np.zeros((len(windows), nb, 3))
        self.torque = np.zeros_like(self.force)
        self._cpg = np.zeros(1)

    def start(self, engine: BasePhysics, rec: Recording, windows: list[Window]) -> None:
        poses, vel = engine_poses(rec), velocities(rec)
        for w, win in enumerate(windows):
            engine.set_state(w, poses[win.start], vel[win.start])
            self.banks[w].state[:, sk.S_LPREV] = _previous_lengths(self.banks[w], poses, rec.time_s, win.start, self.dt)

    def run(self, engine: BasePhysics, k: int, live: np.ndarray) -> None:
        for _ in range(k):
            j = self.step
            poses = engine.read_poses()
            for w in np.flatnonzero(live):
                bank = self.banks[w]
                bank.state[self.recorded, sk.S_REST] = self.rest[w][min(j, self.n_steps - 1)]
                if bank.step(poses[w], self._cpg, self.dt, sk.MOTOR_PHYSICAL) != sk.STATUS_OK:
                    live[w] = False
                if j in self.check[w]:
                    row = self.check[w][j]
                    self.runs[w].poses[row] = poses[w]
                    self.runs[w].tension_n[row] = bank.tension[self.recorded] / NEWTON
                self.force[w], self.torque[w] = bank.force, bank.torque
            engine.apply_wrenches(self.force, self.torque, live)
            engine.step(live)
            self.step += 1


def _batch(setup: TrialSetup, rec: Recording, windows: list[Window], recorded: np.ndarray) -> list[WindowRun | None]:
    shots = _Shots(setup, rec, windows, recorded)
    engine, owned = setup.scene(None, None, len(windows))
    try:
        shots.start(engine, rec, windows)
        active = np.ones(len(windows), dtype=bool)
        advance(engine, lambda k, live: shots.run(engine, k, live), shots.n_steps, active, shots.n_steps)
        live = active & np.array([shots.n_steps in c for c in shots.check])
        shots.run(engine, 1, live)  # the last checked rows: their poses and the tensions those poses make
        return [None if w in engine.retries else shots.runs[w] for w in range(len(windows))]
    finally:
        if owned:
            engine.close()


def _lengths(bank: sk.StringBank, poses: np.ndarray) -> np.ndarray:
    """(n_strings,) anchor-to-anchor lengths (cm) at poses (nb, 7)."""
    sk.world_anchors(poses, bank.body_a, bank.anchor_a, bank.wa)
    sk.world_anchors(poses, bank.body_b, bank.anchor_b, bank.wb)
    return np.linalg.norm(bank.wb - bank.wa, axis=1)


def _previous_lengths(bank: sk.StringBank, poses: np.ndarray, t: np.ndarray, row: int, dt: float) -> np.ndarray:
    """The strings' lengths one step before the recorded row (its lengths less dt times their rate, a central
    difference of the recorded samples): the damping's first rate is then the recorded one."""
    lo, hi = max(row - 1, 0), min(row + 1, len(t) - 1)
    rate = (_lengths(bank, poses[hi]) - _lengths(bank, poses[lo])) / (t[hi] - t[lo])
    return _lengths(bank, poses[row]) - rate * dt
