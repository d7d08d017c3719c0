"""Readers into a Recording (worker.fit.recording): the spinefarm format, `spinefarm trial --record` files,
NTRT's recordings (cm, Y up, ground top at 1.5 cm) and a plain CSV of segment poses with units in its header.

`read_recording(path)` picks the reader from what the path is; every reader refuses what it cannot read with
one line naming what it found and what it expected.
"""

from __future__ import annotations

import csv
import gzip
import json
import re
from pathlib import Path

import numpy as np

from spinefarm.robot.scene import GROUND_TOP_CM
from spinefarm.worker.fit.recording import FORMAT, Recording, RecordingError

NTRT_GROUND_TOP_CM = 1.5  # ntrt-spec.md section 1: NTRT's ground box has its top at y = 1.5 cm
NTRT_FORCE_N = 0.01  # NTRT's force unit with kg and cm: kg cm/s^2 = 0.01 N
LENGTH_UNITS_M = {"m": 1.0, "cm": 0.01, "mm": 0.001}
POSE_FIELDS = ("x", "y", "z", "qw", "qx", "qy", "qz")


def read_recording(path: Path | str) -> Recording:
    """A Recording from a spinefarm .npz (its own format or `trial --record`'s), an NTRT run folder (or its
    trajectory.csv.gz) or a pose CSV with units in its header."""
    path = Path(path)
    if path.is_dir():
        return read_ntrt(path)
    if not path.exists():
        raise RecordingError("no such recording", received=str(path), expected="an existing file or NTRT run folder")
    if path.name.endswith(".csv.gz") and (path.parent / "model-meta.txt").exists():
        return read_ntrt(path.parent)
    if path.suffix == ".npz":
        return read_npz(path)
    if path.suffix == ".csv":
        return read_pose_csv(path)
    raise RecordingError("unknown recording kind", received=path.name,
                         expected=".npz (spinefarm), .csv (poses with units), or an NTRT run folder")


def read_npz(path: Path) -> Recording:
    with np.load(path, allow_pickle=False) as z:
        keys = set(z.files)
        if "format" in keys:
            return _read_native(z, path)
        if {"time_s", "poses"} <= keys:
            return _read_trial_record(z, path)
    raise RecordingError(f"{path}: not a recording", received=sorted(keys),
                         expected=f"format={FORMAT!r} or a `spinefarm trial --record` file (time_s, poses)")


def _read_native(z: np.lib.npyio.NpzFile, path: Path) -> Recording:
    if str(z["format"]) != FORMAT:
        raise RecordingError(f"{path}: unknown recording format", received=str(z["format"]), expected=FORMAT)
    opt = {k: z[k] for k in ("string_length_m", "rest_length_m", "tension_n") if k in z.files}
    return Recording(time_s=z["time_s"], position_m=z["position_m"], quat_wxyz=z["quat_wxyz"],
                     drive=json.loads(str(z["drive_json"])), scene=json.loads(str(z["scene_json"])),
                     morphology=str(z["morphology"]), source=str(path), **opt)


def _read_trial_record(z: np.lib.npyio.NpzFile, path: Path) -> Recording:
    """`spinefarm trial --record`: the trajectory's arrays, the parameters and trial config as JSON."""
    config = json.loads(str(z["trial_config_json"])) if "trial_config_json" in z.files else {}
    params = json.loads(str(z["params_json"])) if "params_json" in z.files else {}
    return from_trajectory({k: z[k] for k in z.files}, config, params, str(path),
                           str(z["morphology"]) if "morphology" in z.files else "")


def from_trajectory(arrays: dict[str, np.ndarray], config: dict, params: dict, source: str = "",
                    morphology: str = "") -> Recording:
    """A Recording of a trial's trajectory (worker.trial.batch.Trajectory.arrays(): poses (n, nb, 7) cm + quaternion
    (x, y, z, w), rest lengths in cm, tensions in N) under its trial config (a dict) and named parameters."""
    poses = arrays["poses"]
    rest = arrays["rest_length_cm"] * 0.01 if "rest_length_cm" in arrays else None
    return Recording(time_s=arrays["time_s"], position_m=poses[:, :, :3] * 0.01, quat_wxyz=poses[:, :, [6, 3, 4, 5]],
                     rest_length_m=rest, tension_n=arrays.get("tension_n"),
                     drive={"kind": "controller", "controller": config.get("controller"), "params": params},
                     scene=config.get("scene", {}), source=source, morphology=morphology)


def read_ntrt(folder: Path) -> Recording:
    """An NTRT run folder (trajectory.csv.gz, model-meta.txt): cm -> m, NTRT's ground top (y = 1.5 cm) onto
    ours, tensions in NTRT's kg cm/s^2 -> N. The strings were driven by the recorded rest lengths."""
    path = folder / "trajectory.csv.gz"
    if not path.exists():
        raise RecordingError("not an NTRT run folder", received=str(folder), expected="a folder with trajectory.csv.gz")
    with gzip.open(path, "rt") as fh:
        header, data = _table(csv.reader(fh), path)
    n_seg, n_str = _ntrt_counts(folder / "model-meta.txt")
    idx = _columns(header, ["time_s"] + [f"seg{n}_{f}" for n in range(n_seg) for f in POSE_FIELDS]
                   + [f"m{i}_{f}" for i in range(n_str) for f in ("len", "rest", "tension")], path)
    t = data[:, idx[0]]
    seg = data[:, idx[1:1 + 7 * n_seg]].reshape(len(t), n_seg, 7)
    strings = data[:, idx[1 + 7 * n_seg:]].reshape(len(t), n_str, 3)
    pos = seg[:, :, :3].copy()
    pos[:, :, 1] += GROUND_TOP_CM - NTRT_GROUND_TOP_CM
    return Recording(time_s=t, position_m=pos * 0.01, quat_wxyz=seg[:, :, 3:], string_length_m=strings[:, :, 0] * 0.01,
                     rest_length_m=strings[:, :, 1] * 0.01, tension_n=strings[:, :, 2] * NTRT_FORCE_N,
                     drive={"kind": "rest_lengths"}, scene={"kind": "flat"}, source=str(folder),
                     morphology=folder.parent.name)


def _ntrt_counts(meta: Path) -> tuple[int, int]:
    """(segments, strings) as model-meta.txt lists them: one `segment n:` and one `muscle i:` line each."""
    if not meta.exists():
        raise RecordingError("not an NTRT run folder", received=f"no {meta.name} in {meta.parent}",
                             expected="model-meta.txt beside trajectory.csv.gz")
    lines = meta.read_text().splitlines()
    return sum(line.startswith("segment ") for line in lines), sum(line.startswith("muscle ") for line in lines)


def read_pose_csv(path: Path) -> Recording:
    """A pose CSV such as a motion-capture export: `time_s` (or `time_ms`), per segment n the columns
    seg<n>_x_<u>, seg<n>_y_<u>, seg<n>_z_<u> (u: m, cm or mm; Y up) and seg<n>_qw, _qx, _qy, _qz; optionally
    per string i `str<i>_rest_<u>`, the commanded rest lengths that drove the robot."""
    with open(path, newline="") as fh:
        header, data = _table(csv.reader(fh), path)
    time_col = next((c for c in ("time_s", "time_ms") if c in header), None)
    if time_col is None:
        raise RecordingError(f"{path}: no time column", received=header[:3], expected="time_s or time_ms first")
    n_seg = _count(header, r"seg(\d+)_x_[a-z]+$")
    if n_seg == 0:
        raise RecordingError(f"{path}: no segment columns", received=header[:4],
                             expected="seg0_x_<unit>, seg0_y_<unit>, ... with unit m, cm or mm")
    names, scale = [], []
    for n in range(n_seg):
        for axis in "xyz":
            col = next((c for c in header if re.fullmatch(rf"seg{n}_{axis}_[a-z]+", c)), f"seg{n}_{axis}_<unit>")
            names.append(col)
            scale.append(_unit(col, path))
        names += [f"seg{n}_{f}" for f in ("qw", "qx", "qy", "qz")]
    idx = _columns(header, [time_col, *names], path)
    t = data[:, idx[0]] * (0.001 if time_col == "time_ms" else 1.0)
    seg = data[:, idx[1:]].reshape(len(t), n_seg, 7)
    pos = seg[:, :, :3] * np.array(scale).reshape(n_seg, 3)
    rest_cols = sorted((c for c in header if re.fullmatch(r"str\d+_rest_[a-z]+", c)),
                       key=lambda c: int(c[3:c.index("_")]))
    rest = None
    if rest_cols:
        rest = data[:, _columns(header, rest_cols, path)] * np.array([_unit(c, path) for c in rest_cols])
    return Recording(time_s=t, position_m=pos, quat_wxyz=seg[:, :, 3:], rest_length_m=rest,
                     drive={"kind": "rest_lengths"} if rest is not None else _sidecar_drive(path),
                     scene={"kind": "flat"}, source=str(path))


def _sidecar_drive(path: Path) -> dict:
    """A pose CSV without rest lengths names its controller in <file>.drive.json: {"controller", "params"}."""
    side = path.with_suffix(".drive.json")
    if not side.exists():
        raise RecordingError(f"{path}: nothing says what drove the robot", received="no str<i>_rest_<unit> columns",
                             expected=f"rest-length columns or {side.name} with controller and params")
    return {"kind": "controller", **json.loads(side.read_text())}


def _unit(col: str, path: Path) -> float:
    unit = col.rsplit("_", 1)[1]
    if unit not in LENGTH_UNITS_M:
        raise RecordingError(f"{path}: column {col} has an unknown length unit", received=unit,
                             expected=f"one of {sorted(LENGTH_UNITS_M)}")
    return LENGTH_UNITS_M[unit]


def _table(rows: object, path: Path) -> tuple[list[str], np.ndarray]:
    it = iter(rows)  # type: ignore[call-overload]
    header = [h.strip() for h in next(it, [])]
    body = [r for r in it if r]
    if not header or not body:
        raise RecordingError(f"{path}: empty table", received=f"{len(body)} rows", expected="a header and rows")
    width = {len(r) for r in body}
    if width != {len(header)}:
        bad = next(i for i, r in enumerate(body) if len(r) != len(header))
        raise RecordingError(f"{path}: row {bad + 1} has {len(body[bad])} fields", received=len(body[bad]),
                             expected=f"{len(header)} fields as the header")
    try:
        return header, np.array(body, dtype=float)
    except ValueError as exc:
        raise RecordingError(f"{path}: a value is not a number", received=str(exc).split(": ")[-1],
                             expected="numbers in every column") from exc


def _count(header: list[str], pattern: str) -> int:
    found = sorted(int(m.group(1)) for h in header if (m := re.match(pattern, h)))
    return found[-1] + 1 if found else 0


def _columns(header: list[str], wanted: list[str], path: Path) -> list[int]:
    missing = [w for w in wanted if w not in header]
    if missing:
        raise RecordingError(f"{path}: missing column{'s' if len(missing) > 1 else ''}",
                             received=", ".join(missing[:3]) + (" ..." if len(missing) > 3 else ""),
                             expected=f"{len(wanted)} columns: {', '.join(wanted[:4])} ...")
    return [header.index(w) for w in wanted]
