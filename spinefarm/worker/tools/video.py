"""A trial's motion as a video for papers and talks: one matplotlib frame per recorded frame, in real time.

GIF through Pillow (matplotlib brings it); MP4 (H.264) through an ffmpeg binary: the one the `video` extra
installs (imageio-ffmpeg ships it) or an `ffmpeg` on PATH. The camera follows the centre of mass; strings are
coloured by tension as in the gait pictures, the path of the centre of mass is drawn on the ground.
"""

from __future__ import annotations

import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from spinefarm.protocol.errors import ConfigError

WIDTH_PX, HEIGHT_PX, DPI = 960, 540, 120
VIDEO_SUFFIXES = (".mp4", ".gif")
TRAIL_COLOUR = "#2e9e5b"


def ffmpeg_exe() -> str | None:
    """An ffmpeg binary: imageio-ffmpeg's (pip install 'spinefarm[video]') or one on PATH; None without."""
    try:
        import imageio_ffmpeg

        return str(imageio_ffmpeg.get_ffmpeg_exe())
    except (ImportError, RuntimeError):
        return shutil.which("ffmpeg")


def check_video_path(path: str | Path) -> Path:
    """The output path, refused before any simulation when its kind cannot be written here."""
    p = Path(path)
    if p.suffix.lower() not in VIDEO_SUFFIXES:
        raise ConfigError("--video takes an .mp4 or .gif file", received=str(path), expected="gait.mp4 or gait.gif")
    if p.suffix.lower() == ".mp4" and ffmpeg_exe() is None:
        raise ConfigError("an .mp4 needs an encoder", received="no ffmpeg here",
                          expected="pip install 'spinefarm[video]' (or apt-get install ffmpeg), or --video gait.gif")
    return p


def frame_interval_s(motion: dict[str, Any]) -> float:
    t = np.asarray(motion["time_s"], dtype=float)
    return float(np.median(np.diff(t))) if len(t) > 1 else 1 / 30


def gif_durations_ms(motion: dict[str, Any]) -> list[int]:
    """Per-frame GIF delays (GIF counts in 10 ms): whole centiseconds that add up to the recorded times."""
    cs = np.round(100 * np.asarray(motion["time_s"], dtype=float)).astype(int)
    last = max(1, round(100 * frame_interval_s(motion)))
    return [10 * int(max(1, d)) for d in np.diff(cs)] + [10 * last]


def _posed(motion: dict[str, Any], i: int) -> tuple[np.ndarray, np.ndarray]:
    """World rod ends (n_rods, 2, 3) and string ends (n_strings, 2, 3) of frame i, in cm."""
    from spinefarm.worker.tools.render import _rotation

    poses = np.asarray(motion["poses"][i], dtype=float).reshape(-1, 7)
    rots = [_rotation(p[3:7]) for p in poses]

    def world(body: int, local: list[float]) -> np.ndarray:
        return poses[body, :3] + rots[body] @ np.asarray(local, dtype=float)

    rods = np.array([[world(r["body"], r["a_cm"]), world(r["body"], r["b_cm"])] for r in motion["rods"]])
    strings = np.array([[world(s["body_a"], s["anchor_a_cm"]), world(s["body_b"], s["anchor_b_cm"])]
                        for s in motion["strings"]])
    return rods, strings


def _ground_grid(u: float, v: float, half: float, step: float, height: float) -> list[np.ndarray]:
    """Lines of a ground grid of `step` cm fixed in the world, over the window u, v +- half (plot axes)."""
    lines = []
    for k in np.arange(np.ceil((u - half) / step), np.floor((u + half) / step) + 1):
        lines.append(np.array([[k * step, v - half, height], [k * step, v + half, height]]))
    for k in np.arange(np.ceil((v - half) / step), np.floor((v + half) / step) + 1):
        lines.append(np.array([[u - half, k * step, height], [u + half, k * step, height]]))
    return lines


def rgb_frames(motion: dict[str, Any], title: str | None = None) -> Iterator[np.ndarray]:
    """(HEIGHT_PX, WIDTH_PX, 3) uint8 pictures, one per recorded frame."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    cmap = matplotlib.colormaps["coolwarm"]
    tmax = motion["tension_max_n"] or 1.0
    com = np.asarray(motion["com_cm"], dtype=float)
    rods0, strings0 = _posed(motion, 0)
    half = 0.45 * max(30.0, float(np.ptp(rods0.reshape(-1, 3), axis=0).max()))
    grid_cm = 10.0 ** np.floor(np.log10(half / 2))
    ground = motion["ground_top_cm"]
    fig = plt.figure(figsize=(WIDTH_PX / DPI, HEIGHT_PX / DPI), dpi=DPI)
    ax = fig.add_axes((0, 0, 1, 1), projection="3d", computed_zorder=False)
    strings = Line3DCollection(list(strings0[..., [2, 0, 1]]), linewidths=1.0, zorder=1)
    rods = Line3DCollection(list(rods0[..., [2, 0, 1]]), colors="#1f1f1f", linewidths=2.2, zorder=2)
    ax.add_collection3d(strings, autolim=False)
    ax.add_collection3d(rods, autolim=False)
    grid = Line3DCollection([], colors="#cfc9b9", linewidths=0.6, zorder=0)
    ax.add_collection3d(grid, autolim=False)
    (trail,) = ax.plot([], [], [], color=TRAIL_COLOUR, linewidth=1.5, zorder=0)
    label = fig.text(0.02, 0.95, "", fontsize=10)
    fig.text(0.02, 0.02, title or motion.get("title", ""), fontsize=8, color="#444")
    ax.view_init(elev=22, azim=-60)
    ax.set_box_aspect((1, 1, 0.4), zoom=1.5)
    ax.set_axis_off()
    for i, t in enumerate(motion["time_s"]):
        r, s = _posed(motion, i)
        # plot axes: z along the spine, x across, y up (as the gait pictures)
        rods.set_segments(r[..., [2, 0, 1]])
        strings.set_segments(s[..., [2, 0, 1]])
        strings.set_color(cmap(np.asarray(motion["tension_n"][i], dtype=float) / tmax))
        trail.set_data_3d(com[: i + 1, 2], com[: i + 1, 0], np.full(i + 1, ground))
        c = com[i]
        ax.set_xlim(c[2] - half, c[2] + half)
        ax.set_ylim(c[0] - half, c[0] + half)
        ax.set_zlim(ground, ground + 0.8 * half)
        grid.set_segments(_ground_grid(c[2], c[0], half, grid_cm, ground))
        label.set_text(f"{t:.2f} s")
        fig.canvas.draw()
        yield np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
    plt.close(fig)


def write_video(motion: dict[str, Any], out: str | Path, title: str | None = None) -> tuple[Path, int]:
    """Write the motion as out (.mp4 or .gif) in real time; returns (path, frames written)."""
    path = check_video_path(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    interval = frame_interval_s(motion)
    frames = rgb_frames(motion, title)
    if path.suffix.lower() == ".gif":
        from PIL import Image

        images = [Image.fromarray(f).quantize(colors=128, method=Image.Quantize.MEDIANCUT) for f in frames]
        images[0].save(path, save_all=True, append_images=images[1:], duration=gif_durations_ms(motion), loop=0,
                       optimize=False, disposal=1)
        return path, len(images)
    return path, _encode_mp4(frames, path, 1.0 / interval)


def _encode_mp4(frames: Iterator[np.ndarray], path: Path, fps: float) -> int:
    cmd = [str(ffmpeg_exe()), "-y", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "rgb24",
           "-s", f"{WIDTH_PX}x{HEIGHT_PX}", "-r", f"{fps:.6g}", "-i", "-", "-an", "-c:v", "libx264",
           "-pix_fmt", "yuv420p", "-crf", "22", "-movflags", "+faststart", str(path)]
    proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stderr=subprocess.PIPE)
    n = 0
    try:
        for f in frames:
            proc.stdin.write(f.tobytes())
            n += 1
    finally:
        proc.stdin.close()
        err = proc.stderr.read().decode(errors="replace")
        proc.wait()
    if proc.returncode != 0:
        raise ConfigError("ffmpeg could not write the video", received=err.strip()[-300:] or proc.returncode,
                          expected=f"an H.264 {path.name}")
    return n
