"""Replaying NTRT's published gaits (spec 4.4, 4.5, 8): read the .nnw files, map them into the NTRT
controller space, run the NTRT-era morphology with that code's motor at 1 ms, compare with NTRT's figure.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from spinefarm.protocol.errors import ConfigError, MorphologySpecError
from spinefarm.protocol.params import ParamSpace
from spinefarm.protocol.results import TrialResult
from spinefarm.robot.engines import DEFAULT_ENGINE
from spinefarm.robot.morphology.model import Morphology
from spinefarm.robot.spaces import NtrtTableSpace, controller_space

# NTRT folder name -> built-in NTRT-era morphology
ROBOT_FOLDERS = {
    "TetraSpine": "tetraspine-ntrt",
    "TetrahedralComplex": "tetrahedral-complex",
    "OctahedralComplex": "octahedral-complex",
    "Ribbed": "ribbed",
    "ribDemo": "ribbed",
}


# NTRT's recorded runs (ntrt-recordings: a run-info.json beside params/) were made with NTRT's current code;
# a robot whose model of that code exists runs on it
RECORDED_RUN_MORPHOLOGY = {"tetraspine-ntrt": "tetraspine-ntrt2026", "ribbed": "ribbed-ntrt2026",
                           "octahedral-complex": "octahedral-complex-ntrt2026",
                           "tetrahedral-complex": "tetrahedral-complex-ntrt2026"}


def ntrt_motor(morph: Morphology) -> str:
    """The NTRT motor of the code the morphology mirrors (extra.ntrt_code_year; 2014 when not said)."""
    return "ntrt2026" if dict(morph.extra).get("ntrt_code_year", 2014) >= 2026 else "ntrt2014"


def recorded_run(folder: str | Path) -> NtrtReference | None:
    """NTRT's own distance for a recorded run's folder (its run-info.json), or None for a bare .nnw folder."""
    info_path = Path(folder) / "run-info.json"
    if not info_path.is_file():
        return None
    try:
        info = json.loads(info_path.read_text())
        dist = info["runs"]["A"]["dist"]
        steps = int(info["steps"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ConfigError("run-info.json is not an NTRT recording's", received=str(info_path),
                          expected="JSON with steps and runs.A.dist (ntrt-recordings/README.md)") from exc
    if not dist:  # an aborted run has no score
        return None
    return NtrtReference(float(dist), steps * 0.001, f"NTRT's recorded run ({info_path})")


# NTRT's published parameter sets ship with the package (data, Apache-2.0: LICENSE and NOTICE beside them)
PUBLISHED_DIR = Path(__file__).resolve().parents[1] / "replay_data"
PUBLISHED = {name: PUBLISHED_DIR / folder / "paper-2014-06-07" for folder, name in ROBOT_FOLDERS.items()
             if folder != "ribDemo"}


def parameter_folder(where: str | Path) -> Path:
    """A folder of .nnw files: an existing path, or the shipped set of a robot named in PUBLISHED."""
    path = Path(where)
    if path.is_file():  # a spec file, say: its robot has no published parameters to replay
        raise ConfigError("replay needs NTRT's parameters, not a file", received=str(where),
                          expected=f"one of {', '.join(PUBLISHED)}, or a folder holding logs/bestParameters-*.nnw "
                                   "(with --morphology FILE.yaml to run them on a robot from a spec file); a "
                                   "searched gait replays with `spinefarm trial --run RUN.h5`")
    if path.exists():
        return path
    if str(where) in PUBLISHED:
        return PUBLISHED[str(where)]
    raise ConfigError("no such NTRT parameter folder or robot with published parameters", received=str(where),
                      expected=f"one of {', '.join(PUBLISHED)} or a folder holding logs/bestParameters-*.nnw")


@dataclass(frozen=True)
class NtrtReference:
    """A distance NTRT itself recorded for the published parameters (spec 8)."""

    distance_cm: float
    duration_s: float
    source: str


REFERENCES = {
    "octahedral-complex": NtrtReference(98.5485, 30.0, "NTRT replay log f388f0f6 (2014-06-07), 16 identical replays"),
    "tetrahedral-complex": NtrtReference(188.694, 30.0, "NTRT integration test 3a5f0d87 (Oct 2014)"),
}


@dataclass(frozen=True)
class NtrtParameterSet:
    """Both values of every published file: node (u_f, u_A) and edges[i] = (u_w, u_psi) of edge file i."""

    folder: Path
    node: tuple[float, float]
    edges: tuple[tuple[float, float], ...]


@dataclass(frozen=True)
class ReplayReport:
    morphology: str
    scored_segment: int
    folder: Path
    parameters: NtrtParameterSet
    unit_params: np.ndarray
    duration_s: float
    result: TrialResult
    reference: NtrtReference | None
    param_space: ParamSpace  # NTRT's controller space on this robot, which unit_params lie in
    motor_model: str = "ntrt2014"

    @property
    def diverged(self) -> bool:
        return not self.result.ok

    @property
    def speed_cm_s(self) -> float:
        """Speed of the scored segment (NTRT's distance over the simulated time)."""
        t = self.result.sim_time_s
        return self.result.ntrt_distance_cm / t if t > 0 else 0.0

    @property
    def ratio(self) -> float | None:
        """Our scored-segment speed over NTRT's (the distance ratio when the durations agree)."""
        if self.reference is None or self.diverged:
            return None
        return self.speed_cm_s / (self.reference.distance_cm / self.reference.duration_s)


def read_nnw(path: Path) -> tuple[float, float]:
    """Both values of one .nnw file: one line 'a,b' (no trailing newline in NTRT's files)."""
    try:
        text = path.read_text()
    except OSError as exc:
        raise ConfigError("cannot read an NTRT parameter file", received=str(path),
                          expected="a readable .nnw file") from exc
    parts = [p.strip() for p in text.strip().split(",")]
    try:
        values = [float(p) for p in parts]
    except ValueError as exc:
        raise ConfigError(f"{path.name} is not two comma-separated numbers", received=text[:80],
                          expected="'u1,u2' with both values in [0, 1]") from exc
    if len(values) != 2 or not all(0.0 <= v <= 1.0 for v in values):
        raise ConfigError(f"{path.name} does not hold two values in [0, 1]", received=text[:80],
                          expected="'u1,u2' with both values in [0, 1]")
    return values[0], values[1]


def read_parameter_set(folder: str | Path, suffix: str = "default") -> NtrtParameterSet:
    """The node file and edge files 0..N-1 of `folder` (or its logs/ subfolder)."""
    root = Path(folder)
    # NTRT's own logs/, a recording's params/ (ntrt-recordings), or the files themselves
    logs = next((root / sub for sub in ("logs", "params") if (root / sub).is_dir()), root)
    if not logs.is_dir():
        raise ConfigError("NTRT parameter folder not found", received=str(root),
                          expected="a folder holding logs/bestParameters-*.nnw")
    node_file = logs / f"bestParameters-{suffix}_node-0.nnw"
    if not node_file.exists():
        raise ConfigError("no NTRT node parameter file", received=str(node_file),
                          expected=f"bestParameters-{suffix}_node-0.nnw in {logs}")
    pattern = re.compile(rf"bestParameters-{re.escape(suffix)}_edge-(\d+)\.nnw$")
    found = {int(m.group(1)): p for p in logs.iterdir() if (m := pattern.match(p.name))}
    missing = sorted(set(range(len(found))) - set(found))
    if not found or missing:
        raise ConfigError("NTRT edge files are missing or not numbered 0..N-1", received=sorted(found)[:10],
                          expected=f"bestParameters-{suffix}_edge-0.nnw ... contiguous (missing {missing[:5]})")
    edges = tuple(read_nnw(found[i]) for i in range(len(found)))
    return NtrtParameterSet(root, read_nnw(node_file), edges)


def detect_morphology(folder: str | Path) -> str:
    """The built-in NTRT-era morphology named by an NTRT robot folder in `folder`'s path (the model of NTRT's
    current code for a recorded run, where there is one)."""
    for part in reversed(Path(folder).resolve().parts):
        if part in ROBOT_FOLDERS:
            name = ROBOT_FOLDERS[part]
            return RECORDED_RUN_MORPHOLOGY.get(name, name) if (Path(folder) / "run-info.json").is_file() else name
    raise ConfigError("cannot tell the robot from the path", received=str(folder),
                      expected=f"a path through one of {sorted(ROBOT_FOLDERS)}, or --morphology NAME")


def ntrt_space(morph: Morphology) -> NtrtTableSpace:
    """The robot's NTRT controller space, the one published sets are written in."""
    space = controller_space(morph, "ntrt")
    if not isinstance(space, NtrtTableSpace):
        raise MorphologySpecError("replay needs NTRT's controller space", received=type(space).__name__,
                                  expected="NtrtTableSpace")
    return space


def unit_params(morph: Morphology, params: NtrtParameterSet, space: NtrtTableSpace | None = None) -> np.ndarray:
    """Unit-cube vector of the NTRT space: edge file i fills coupling slot N_e - 1 - i."""
    return (space or ntrt_space(morph)).unit_from_ntrt_files(params.node, list(params.edges))


def replay(folder: str | Path, morphology: str | Morphology | None = None, *, duration_s: float | None = None,
           suffix: str = "default", seed: int = 0, pose_jitter_cm: float = 0.0,
           engine: str = DEFAULT_ENGINE, profile: Mapping[str, float] | None = None,
           motor_model: str | None = None, engine_options: Mapping[str, object] | None = None) -> ReplayReport:
    """Run NTRT's published parameters on the NTRT-era morphology (the motor of its NTRT code, 1 ms, one
    sub-step, no friction anchors in Bullet; `engine` "mujoco" runs the same on MuJoCo's default contacts),
    under a profile's constants if given (robot.profile) and engine options over these. A recorded run's folder
    is compared with NTRT's recorded distance."""
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.worker.trial.simulation import TrialConfig, simulate

    morph = load_morphology(morphology or detect_morphology(folder))
    params = read_parameter_set(folder, suffix)
    space = ntrt_space(morph)
    u = unit_params(morph, params, space)
    duration = duration_s or morph.duration_s
    # NTRT's Bullet 2.81 had no friction anchors; its motor caps are per 1 ms step (spec 0a.3)
    # and its CPG runs every step, as controlTime 0.001 fixes it (cpg_step_s 0)
    motor_model = motor_model or ntrt_motor(morph)
    own = {"friction_anchor": False} if engine == "bullet" else {}
    cfg = TrialConfig(duration_s=duration, dt_s=0.001, motor_model=motor_model, controller="ntrt", cpg_step_s=0.0,
                      engine=engine, engine_options={**own, **(engine_options or {})},
                      pose_jitter_cm=pose_jitter_cm, profile=dict(profile or {}))
    result = simulate(morph, u, cfg, seed).result
    reference = recorded_run(folder) or REFERENCES.get(morph.name)
    return ReplayReport(morph.name, morph.scored_segment, Path(folder), params, u, duration, result, reference,
                        space.param_space, motor_model)


def gait_file(report: ReplayReport) -> dict:
    """The replayed parameter set as a `spinefarm trial --params` file (named physical values of NTRT's
    controller space): to run it under this model's own defaults, or to start a search from it (--enqueue)."""
    r, space = report.result, report.param_space
    return {"morphology": report.morphology, "controller": "ntrt",
            "params": space.to_named(space.from_unit(report.unit_params)),
            "source": {"ntrt_parameters": str(report.parameters.folder),
                       "replay": f"NTRT's motor {report.motor_model}, dt 1 ms",
                       "ntrt_distance_cm": r.ntrt_distance_cm, "speed_cm_s": r.speed_cm_s, "cot": r.cot,
                       "sim_time_s": r.sim_time_s}}


JITTER_CM = 1e-6  # spec 0a.5: perturbations this small already spread the tetrahedral complex's distance


def replay_spread(folder: str | Path, morphology: str | Morphology | None, seeds: int, *,
                  duration_s: float | None = None, suffix: str = "default", engine: str = DEFAULT_ENGINE,
                  profile: Mapping[str, float] | None = None, motor_model: str | None = None) -> list[ReplayReport]:
    """Replays with the start pose jittered by JITTER_CM (seeds 1..seeds): a distribution, not one sample."""
    return [replay(folder, morphology, duration_s=duration_s, suffix=suffix, seed=s, pose_jitter_cm=JITTER_CM,
                   engine=engine, profile=profile, motor_model=motor_model)
            for s in range(1, seeds + 1)]

