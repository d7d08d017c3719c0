"""Headless pictures of a structure: rods dark, strings coloured by tension (blue low, red high, as the
paper's figures), from the build pose or from recorded poses; a strip of keyframes with their times.

Pure geometry from robot.bodies and the string anchors; matplotlib with the Agg backend.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from spinefarm.protocol.errors import ConfigError
from spinefarm.robot.bodies import BodyModel, StringGeometry, build_bodies, build_strings
from spinefarm.robot.morphology.model import Morphology
from spinefarm.worker.sim.strings import world_anchors

ROD_COLOUR = "#1f1f1f"
GROUND_COLOUR = "#d9d4c7"
GROUND_TOP_CM = 0.5


@dataclass(frozen=True)
class Frame:
    """One picture's data: time_s, poses (n_bodies, 7) COM cm + quaternion xyzw, tension_n (n_strings,)."""

    time_s: float
    poses: np.ndarray
    tension_n: np.ndarray


def _rotation(q: np.ndarray) -> np.ndarray:
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def rod_segments(bodies: list[BodyModel], poses: np.ndarray) -> np.ndarray:
    """(n_rods, 2, 3) world end points (cm) of every rod, bodies posed by poses (n_bodies, 7)."""
    out = []
    for body, pose in zip(bodies, poses, strict=True):
        r = _rotation(pose[3:7])
        for rod in body.rods:
            half = rod.rotation @ np.array([0.0, rod.length_cm / 2, 0.0])
            ends = np.array([rod.centre_cm - half, rod.centre_cm + half])
            out.append(pose[:3] + ends @ r.T)
    return np.array(out)


def string_segments(geom: StringGeometry, poses: np.ndarray) -> np.ndarray:
    """(n_strings, 2, 3) world anchor points (cm) of every string."""
    n = len(geom.start_length_cm)
    a = np.empty((n, 3))
    b = np.empty((n, 3))
    p = np.ascontiguousarray(poses, dtype=float)
    world_anchors(p, geom.body_a, geom.anchor_a_cm, a)
    world_anchors(p, geom.body_b, geom.anchor_b_cm, b)
    return np.stack([a, b], axis=1)


def initial_frame(bodies: list[BodyModel], n_strings: int) -> Frame:
    """The build pose: identity orientations, every string at its start rest length (no tension)."""
    poses = np.array([[*b.com_cm, 0.0, 0.0, 0.0, 1.0] for b in bodies])
    return Frame(0.0, poses, np.zeros(n_strings))


def frames_from_record(record: dict[str, np.ndarray], n_frames: int, n_bodies: int, n_strings: int) -> list[Frame]:
    """n_frames keyframes evenly spaced over a recorded trajectory (Trajectory.arrays() layout)."""
    for key in ("time_s", "poses", "tension_n"):
        if key not in record:
            raise ConfigError("the record lacks an array", received=sorted(record), expected=f"a {key!r} array")
    t, poses, tension = record["time_s"], record["poses"], record["tension_n"]
    if poses.ndim != 3 or poses.shape[1:] != (n_bodies, 7) or tension.shape[1:] != (n_strings,):
        raise ConfigError("the record does not fit this morphology",
                          received=f"poses {poses.shape}, tension {tension.shape}",
                          expected=f"poses (n, {n_bodies}, 7) and tension (n, {n_strings})")
    if len(t) == 0:
        raise ConfigError("the record is empty", received=0, expected="at least one recorded sample")
    idx = np.unique(np.round(np.linspace(0, len(t) - 1, max(1, n_frames))).astype(int))
    return [Frame(float(t[i]), poses[i], tension[i]) for i in idx]


def _to_plot(p: np.ndarray) -> np.ndarray:
    """World (x, y up, z) -> plot axes (z along the spine, x across, y up)."""
    return p[..., [2, 0, 1]]


def render(morph: Morphology, frames: list[Frame], out: str | Path, *, tension_max_n: float | None = None,
           title: str | None = None, dpi: int = 110) -> Path:
    """Draw frames side by side into a PNG and return its path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import cm, colors

    if not frames:
        raise ConfigError("nothing to draw", received=0, expected="at least one frame")
    bodies = build_bodies(morph.structure)
    geom = build_strings(morph.structure, bodies)
    rods = [_to_plot(rod_segments(bodies, f.poses)) for f in frames]
    strs = [_to_plot(string_segments(geom, f.poses)) for f in frames]
    lo, hi = _view_box(rods, strs)
    peak = max(float(np.max(f.tension_n)) for f in frames)
    tmax = tension_max_n or (peak if peak > 1e-6 else 1.0)
    norm = colors.Normalize(0.0, tmax)
    cmap = matplotlib.colormaps["coolwarm"]

    n = len(frames)
    cols = min(n, 3)
    rows = -(-n // cols)
    fig = plt.figure(figsize=(5.6 * cols + 1.0, 3.4 * rows + 0.6))
    for i, frame in enumerate(frames):
        ax = fig.add_subplot(rows, cols, i + 1, projection="3d", computed_zorder=False)
        _draw_panel(ax, lo, hi, rods[i], strs[i], cmap(norm(frame.tension_n)), frame.time_s)
    fig.subplots_adjust(left=0.0, right=0.88, bottom=0.02, top=0.9, wspace=0.0, hspace=0.0)
    cax = fig.add_axes((0.89, 0.2, 0.012, 0.6))
    fig.colorbar(cm.ScalarMappable(norm=norm, cmap=cmap), cax=cax, label="string tension (N)")
    fig.suptitle(title or f"{morph.name}: {morph.description}", fontsize=9, wrap=True)
    path = Path(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path


def _view_box(rods: list[np.ndarray], strs: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) plot corners holding every frame's rods and strings, padded, the ground at the bottom."""
    pts = np.concatenate([r.reshape(-1, 3) for r in rods] + [s.reshape(-1, 3) for s in strs])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    lo[2] = min(lo[2], GROUND_TOP_CM)
    span = np.maximum(hi - lo, 1.0)
    pad = 0.08 * span.max()
    lo, hi = lo - pad, hi + pad
    lo[2] = GROUND_TOP_CM
    return lo, hi


def _draw_panel(ax: Any, lo: np.ndarray, hi: np.ndarray, rods: np.ndarray, strs: np.ndarray,
                string_colours: np.ndarray, time_s: float) -> None:
    """One keyframe on its 3D axes: the ground, strings in their tension colours, rods over them."""
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    ground = np.array([[lo[0], lo[1], GROUND_TOP_CM], [hi[0], lo[1], GROUND_TOP_CM],
                       [hi[0], hi[1], GROUND_TOP_CM], [lo[0], hi[1], GROUND_TOP_CM]])
    ax.add_collection3d(Poly3DCollection([ground], facecolor=GROUND_COLOUR, edgecolor="none", alpha=0.5,
                                         zorder=0))
    ax.add_collection3d(Line3DCollection(list(strs), colors=string_colours, linewidths=1.2, zorder=1))
    ax.add_collection3d(Line3DCollection(list(rods), colors=ROD_COLOUR, linewidths=2.4, zorder=2))
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(tuple(hi - lo), zoom=1.2)
    ax.view_init(elev=28, azim=-72)
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_pane_color((1.0, 1.0, 1.0, 0.0))
    ax.set_xlabel("z (cm)", fontsize=7, labelpad=-2)
    ax.set_ylabel("x", fontsize=7, labelpad=-4)
    ax.set_zlabel("y", fontsize=7, labelpad=-4)
    ax.tick_params(labelsize=6, pad=-1)
    ax.text2D(0.02, 0.92, f"{time_s:.2f} s", transform=ax.transAxes, fontsize=10)
