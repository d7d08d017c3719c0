"""Our model against one of NTRT's own recorded runs, column by column over time.

Runs the recording's parameter set (its params/*.nnw) on our model, recorded every 10 ms like NTRT's
trajectory.csv.gz, and prints one JSON object: at each checkpoint time the differences of every segment's
COM (start offset, displacement since t = 0), orientation (angle between the quaternions), and of each
string's length, rest length and tension (NTRT's force unit, kg cm/s^2 = 0.01 N), plus the scored
segment's horizontal displacement, ours and NTRT's. The reader here is a minimal one (columns, units and
timing from the recordings' README: cm, y up, rows at k * 10 ms written after the model step).

    python bench/ntrt_compare.py TetraSpine random-00 [--morphology tetraspine-ntrt] [--motor-model ntrt2014]
        [--duration 1] [--times 0,0.01,0.1,0.5,1] [--engine bullet] [--engine-option KEY=VALUE]
        [--ground-friction MU] [--strings]
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

RECORDINGS = Path("/work/shared/ntrt-recordings")
NTRT_NEWTON = 100.0  # NTRT's force unit is kg cm/s^2: 1 N = 100 of them
ROW_S = 0.01  # NTRT wrote a row every 10 steps of 1 ms


def read_recording(folder: Path) -> dict:
    """trajectory.csv.gz as arrays: time_s (n,), pos_cm (n, seg, 3), quat_wxyz (n, seg, 4), and per string
    len_cm, rest_cm, tension (n, strings); plus start lengths from model-meta.txt and run-info.json."""
    import pandas as pd

    d = pd.read_csv(folder / "trajectory.csv.gz")
    n_seg = 1 + max(int(m.group(1)) for c in d.columns if (m := re.match(r"seg(\d+)_x$", c)))
    n_str = 1 + max(int(m.group(1)) for c in d.columns if (m := re.match(r"m(\d+)_len$", c)))
    pos = np.stack([d[[f"seg{s}_{a}" for a in "xyz"]].to_numpy() for s in range(n_seg)], axis=1)
    quat = np.stack([d[[f"seg{s}_q{a}" for a in "wxyz"]].to_numpy() for s in range(n_seg)], axis=1)
    meta = (folder / "model-meta.txt").read_text()
    start = [float(x) for x in re.findall(r"start_length=([-\d.eE+]+)", meta)]
    info = json.loads((folder / "run-info.json").read_text())
    return {"time_s": d["time_s"].to_numpy(), "pos_cm": pos, "quat_wxyz": quat,
            "len_cm": d[[f"m{i}_len" for i in range(n_str)]].to_numpy(),
            "rest_cm": d[[f"m{i}_rest" for i in range(n_str)]].to_numpy(),
            "tension": d[[f"m{i}_tension" for i in range(n_str)]].to_numpy(),
            "start_length_cm": np.array(start), "scored_segment": int(info["scoring_segment"]),
            "dist_moved_cm": float(info["runs"]["A"]["dist"]) if info["runs"]["A"]["dist"] else None}


def simulate_ours(folder: Path, morphology: str, motor_model: str, duration_s: float, engine: str,
                  options: dict, ground_friction: float | None = None) -> dict:
    """Our trial of the recording's parameters, recorded every 10 ms, in the recording's layout."""
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.robot.trial_config import TrialConfig
    from spinefarm.worker.tools.replay import read_parameter_set, unit_params
    from spinefarm.worker.trial.simulation import simulate

    morph = load_morphology(morphology)
    u = unit_params(morph, read_parameter_set(folder / "params"))
    cfg = TrialConfig(duration_s=duration_s, dt_s=0.001, motor_model=motor_model, controller="ntrt", engine=engine,
                      engine_options={**({"friction_anchor": False} if engine == "bullet" else {}), **options},
                      record_every_s=ROW_S, ground_friction=ground_friction)
    out = simulate(morph, u, cfg, 0)
    a = out.trajectory.arrays()
    poses = a["poses"][:, :morph.structure.n_segments]
    return {"time_s": a["time_s"], "pos_cm": poses[:, :, :3], "quat_wxyz": poses[:, :, [6, 3, 4, 5]],
            "len_cm": a["length_cm"], "rest_cm": a["rest_length_cm"], "tension": a["tension_n"] * NTRT_NEWTON,
            "scored_segment": morph.scored_segment, "distance_cm": out.result.ntrt_distance_cm,
            "status": out.result.status.value}


def angle_deg(qa: np.ndarray, qb: np.ndarray) -> np.ndarray:
    """Rotation angle between unit quaternions, per row (both w, x, y, z)."""
    dot = np.clip(np.abs(np.sum(qa * qb, axis=-1)), 0.0, 1.0)
    return np.degrees(2.0 * np.arccos(dot))


def checkpoint(ours: dict, ntrt: dict, i: int, j: int, with_strings: bool) -> dict:
    """Differences (ours - NTRT) at our row i and NTRT's row j."""
    s = ntrt["scored_segment"]
    disp_o = ours["pos_cm"][i] - ours["pos_cm"][0]
    disp_n = ntrt["pos_cm"][j] - ntrt["pos_cm"][0]
    row = {"time_s": round(float(ntrt["time_s"][j]), 3),
           "scored_xz_cm": {"ours": float(np.hypot(disp_o[s, 0], disp_o[s, 2])),
                            "ntrt": float(np.hypot(disp_n[s, 0], disp_n[s, 2]))},
           "scored_disp_cm": {"ours": disp_o[s].round(4).tolist(), "ntrt": disp_n[s].round(4).tolist()},
           "pos_offset_cm_max": float(np.abs(ours["pos_cm"][i] - ntrt["pos_cm"][j]).max()),
           "disp_diff_cm_max": float(np.abs(disp_o - disp_n).max()),
           "angle_deg": angle_deg(ours["quat_wxyz"][i], ntrt["quat_wxyz"][j]).round(4).tolist()}
    for col in ("len_cm", "rest_cm", "tension"):
        diff = ours[col][i] - ntrt[col][j]
        row[f"{col}_diff_max"] = float(np.abs(diff).max())
        if with_strings:
            row[f"{col}_ours"] = ours[col][i].round(4).tolist()
            row[f"{col}_ntrt"] = ntrt[col][j].round(4).tolist()
    return row


def compare(spine: str, config: str, morphology: str, motor_model: str, duration_s: float, times: list[float],
            engine: str = "bullet", with_strings: bool = False, options: dict | None = None,
            ground_friction: float | None = None) -> dict:
    folder = RECORDINGS / spine / config
    ntrt = read_recording(folder)
    t0 = time.time()
    ours = simulate_ours(folder, morphology, motor_model, duration_s, engine, options or {}, ground_friction)
    n_ntrt = ntrt["len_cm"].shape[1]  # NTRT records its CPG strings, created after the passive ones (spec 0a.8)
    for col in ("len_cm", "rest_cm", "tension"):
        ours[col] = ours[col][:, -n_ntrt:]
    rows = []
    for t in times:
        i = int(np.searchsorted(ours["time_s"], t - 1e-9))
        j = int(np.searchsorted(ntrt["time_s"], t - 1e-9))
        if i < len(ours["time_s"]) and j < len(ntrt["time_s"]):
            rows.append(checkpoint(ours, ntrt, i, j, with_strings))
    return {"benchmark": "ntrt_compare", "spine": spine, "config": config, "morphology": morphology,
            "motor_model": motor_model, "engine": engine, "engine_options": options or {},
            "ground_friction": ground_friction, "duration_s": duration_s,
            "start_length_diff_cm_max": float(np.abs(ours["len_cm"][0] - ntrt["start_length_cm"]).max()),
            "ntrt_dist_moved_cm": ntrt["dist_moved_cm"], "our_distance_cm": ours["distance_cm"],
            "status": ours["status"], "checkpoints": rows, "wall_s": round(time.time() - t0, 1)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("spine", help="a folder of the recordings: TetraSpine, TetrahedralComplex, ...")
    ap.add_argument("config", help="published, random-00, ...")
    ap.add_argument("--morphology", default="tetraspine-ntrt")
    ap.add_argument("--motor-model", default="ntrt2014")
    ap.add_argument("--engine", default="bullet")
    ap.add_argument("--duration", type=float, default=1.0)
    ap.add_argument("--times", default="0,0.01,0.1,0.5,1")
    ap.add_argument("--engine-option", action="append", default=[], metavar="KEY=VALUE",
                    help="an engine option (JSON value), e.g. solver_iterations=100")
    ap.add_argument("--ground-friction", type=float, default=None, help="the ground's Bullet friction (default 0.5)")
    ap.add_argument("--strings", action="store_true", help="print every string's values, not only the largest gap")
    args = ap.parse_args()
    times = [float(t) for t in args.times.split(",")]
    options = {k: json.loads(v) for k, v in (o.split("=", 1) for o in args.engine_option)}
    print(json.dumps(compare(args.spine, args.config, args.morphology, args.motor_model, args.duration, times,
                             args.engine, args.strings, options, args.ground_friction)))


if __name__ == "__main__":
    main()
