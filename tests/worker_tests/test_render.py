"""Pictures: files are written, hold the drawing, colour strings by tension; the render command."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from spinefarm.cli.main import main
from spinefarm.protocol.errors import ConfigError
from spinefarm.robot.bodies import build_bodies
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.spaces import param_space
from spinefarm.worker.tools.render import Frame, frames_from_record, initial_frame, render, rod_segments
from spinefarm.worker.trial.simulation import TrialConfig, simulate


def _image(path: Path) -> np.ndarray:
    import matplotlib.image as mpimg

    return mpimg.imread(path)[..., :3]


def _dark_fraction(img: np.ndarray) -> float:
    return float((img.max(axis=2) < 0.2).mean())


def test_rod_segments_follow_the_pose():
    morph = load_morphology("tetrahedral-complex")
    bodies = build_bodies(morph.structure)
    frame = initial_frame(bodies, len(morph.structure.strings))
    seg = rod_segments(bodies, frame.poses)
    nodes = morph.structure.node_array()
    np.testing.assert_allclose(seg[0], nodes[[0, 1]], atol=1e-9)  # rod centre -> front of segment 0
    moved = frame.poses.copy()
    moved[:, 0] += 10.0
    moved[:, 3:7] = [0.0, np.sin(np.pi / 4), 0.0, np.cos(np.pi / 4)]  # 90 deg about +Y
    turned = rod_segments(bodies, moved)
    d0 = nodes[1] - nodes[0]
    np.testing.assert_allclose(turned[0, 1] - turned[0, 0], [d0[2], d0[1], -d0[0]], atol=1e-9)


def test_initial_pose_picture(tmp_path: Path):
    morph = load_morphology("octahedral-complex")
    bodies = build_bodies(morph.structure)
    out = render(morph, [initial_frame(bodies, len(morph.structure.strings))], tmp_path / "o.png")
    img = _image(out)
    assert img.shape[0] > 200 and img.shape[1] > 400
    assert _dark_fraction(img) > 0.002  # the rods


def test_trajectory_strip_colours_strings_by_tension(tmp_path: Path):
    morph = load_morphology("tetrahedral-complex")
    bodies = build_bodies(morph.structure)
    u = np.random.default_rng(4).random(len(param_space(morph)))
    rec = simulate(morph, u, TrialConfig(duration_s=0.4, record_every_s=0.05), 0).trajectory.arrays()
    frames = frames_from_record(rec, 3, len(bodies), len(morph.structure.strings))
    assert [f.time_s for f in frames] == pytest.approx([0.0, 0.2, 0.4])
    img = _image(render(morph, frames, tmp_path / "strip.png"))
    assert img.shape[1] > 2 * img.shape[0]
    red = (img[..., 0] > 0.7) & (img[..., 2] < 0.4)
    blue = (img[..., 2] > 0.7) & (img[..., 0] < 0.4)
    assert red.sum() > 20 and blue.sum() > 20


def test_record_that_does_not_fit_is_refused():
    morph = load_morphology("ribbed")
    with pytest.raises(ConfigError, match="does not fit"):
        frames_from_record({"time_s": np.zeros(2), "poses": np.zeros((2, 3, 7)), "tension_n": np.zeros((2, 5))},
                           2, 12, len(morph.structure.strings))
    with pytest.raises(ConfigError, match="lacks"):
        frames_from_record({"time_s": np.zeros(2)}, 2, 12, 5)
    with pytest.raises(ConfigError, match="nothing to draw"):
        render(morph, [], "unused.png")
    assert isinstance(initial_frame(build_bodies(morph.structure), 3), Frame)


def test_render_command(tmp_path: Path, capsys):
    png = tmp_path / "r.png"
    assert main(["render", "ribbed", "--out", str(png)]) == 0
    assert png.stat().st_size > 10_000
    rec = tmp_path / "rec.npz"
    strip = tmp_path / "strip.png"
    assert main(["render", "octahedral-complex", "--out", str(strip), "--duration", "0.3", "--frames", "2",
                 "--record", str(rec)]) == 0
    assert rec.exists() and strip.exists()
    again = tmp_path / "again.png"
    assert main(["render", "octahedral-complex", "--out", str(again), "--record", str(rec), "--frames", "2"]) == 0
    assert _image(again).shape == _image(strip).shape
    assert main(["render", "ribbed", "--out", str(png), "--record", str(rec)]) == 2
    assert "recorded on another morphology" in capsys.readouterr().err
    assert main(["render", "ribbed", "--out", str(png), "--frames", "3"]) == 2
    assert "--frames needs a trajectory" in capsys.readouterr().err
