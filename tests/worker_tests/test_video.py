"""`spinefarm render --video`: the gait as an MP4 or a GIF that decodes, one frame per recorded frame."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from spinefarm.cli.main import main
from spinefarm.worker.tools.motion import record_every_s

ROOT = Path(__file__).resolve().parents[2]


def expected_frames(duration_s: float, dt_s: float = 1e-3) -> int:
    """Frames recorded every record_every_s (rounded to whole steps) from t = 0, plus the end pose."""
    n_steps = round(duration_s / dt_s)
    every = max(1, round(record_every_s(duration_s) / dt_s))
    return len(range(0, n_steps, every)) + 1


def test_mp4_decodes_with_one_frame_per_recorded_frame(tmp_path: Path):
    import imageio_ffmpeg  # the [video] extra (dev installs it)

    out = tmp_path / "gait.mp4"
    assert main(["render", "tetraspine", "--duration", "1", "--random-seed", "3", "--video", str(out)]) == 0
    reader = imageio_ffmpeg.read_frames(str(out))
    meta = next(reader)
    frames = [np.frombuffer(f, np.uint8).reshape(meta["size"][1], meta["size"][0], 3) for f in reader]
    assert len(frames) == expected_frames(1.0) == 32
    assert meta["size"] == (960, 540) and meta["fps"] == pytest.approx(30.3, abs=0.1)  # real time: 33 ms frames
    assert np.abs(frames[0].astype(int) - frames[-1].astype(int)).mean() > 0.5  # the robot moves


def test_gif_of_a_stored_trial(tmp_path: Path, capsys):
    run = tmp_path / "run.h5"
    r = subprocess.run([sys.executable, "-m", "spinefarm", "search", "tetraspine", "--trials", "1", "--workers", "1",
                        "--engine", "bullet", "--duration", "0.5", "--out", str(run), "--api-port", "-1", "--quiet",
                        "--no-verify"],
                       cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    # the search's report names the command this test runs next
    assert f"spinefarm render --run {run} --video best.mp4" in r.stdout
    assert f"spinefarm export {run} --gait best.json" in r.stdout
    out = tmp_path / "best.gif"
    assert main(["render", "--run", str(run), "--video", str(out), "--out", str(tmp_path / "strip.png")]) == 0
    with Image.open(out) as im:
        assert im.n_frames == expected_frames(0.5) and im.size == (960, 540)
        delays = []
        for k in range(im.n_frames):
            im.seek(k)
            delays.append(im.info["duration"])
        last = np.asarray(im.convert("RGB"))
    assert sum(delays[:-1]) == pytest.approx(500, abs=10)  # real time: the frames add up to the trial's 0.5 s
    assert (last < 80).all(axis=2).mean() > 0.002  # dark rods drawn on the last frame
    assert "video frames" in capsys.readouterr().out
    assert (tmp_path / "strip.png").stat().st_size > 10_000


def test_bad_video_names_are_refused_before_any_work(tmp_path: Path, capsys):
    assert main(["render", "tetraspine", "--video", str(tmp_path / "gait.avi")]) != 0
    err = capsys.readouterr().err
    assert "--video has the wrong extension" in err and "gait.avi" in err and ".mp4 or .gif" in err
    assert len(err.strip().splitlines()) == 1
    assert main(["render", "tetraspine", "--trial-id", "3", "--video", str(tmp_path / "gait.gif")]) != 0
    assert "--trial-id needs --run" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())
