"""The fit: engines start from a written state, a held-out recording never enters the loss, and a fit recovers
constants it knows from our own recordings (a tiny robot, short)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from spinefarm.cli.main import main
from spinefarm.robot.bodies import build_bodies
from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.scene import SceneConfig, build_terrain
from spinefarm.worker.engines.base import engine_class
from spinefarm.worker.fit.identify import identify


@pytest.mark.parametrize("engine", ["bullet", "mujoco"])
def test_set_state_writes_every_body(engine):
    bodies = build_bodies(load_morphology("tetraspine-ntrt").structure)
    terrain = build_terrain(SceneConfig(), 0.5, (-100.0, 100.0))
    cls = engine_class(engine)
    with cls(bodies, terrain, 0.001, cls.settings_from_options({}), n_worlds=2) as world:
        poses = np.array([[1.0 + b, 20.0, 3.0 * b, *(np.array([0.1, 0.2, 0.3, 0.9]) / np.sqrt(0.95))]
                          for b in range(3)])
        vel = np.array([[1.0, -2.0, 3.0, 0.1, 0.2, -0.3]] * 3) * np.arange(1, 4)[:, None]
        world.set_state(1, poses, vel)
        assert world.read_poses()[1] == pytest.approx(poses, abs=1e-12)
        assert world.velocities()[1] == pytest.approx(vel, abs=1e-9)
        assert world.read_poses()[0] != pytest.approx(poses)  # the other world untouched


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    folder = tmp_path_factory.mktemp("recs")
    for seed, profile in ((1, "ground_friction: 0.65"), (2, "ground_friction: 0.4"), (3, "ground_friction: 1.2")):
        (folder / f"p{seed}.yaml").write_text(f"constants: {{{profile}}}\n")
        assert main(["trial", "tetraspine-ntrt", "--random-seed", str(seed), "--duration", "0.4", "--engine",
                     "mujoco", "--record", str(folder / f"r{seed}.npz"), "--record-every", "0.001",
                     "--profile", str(folder / f"p{seed}.yaml"), "--json"]) in (0, 1)
    return folder


def _fit(folder, hold_out, capsys) -> dict:
    capsys.readouterr()
    assert main(["fit", "tetraspine-ntrt", str(folder / "r1.npz"), "--engine", "mujoco", "--fit",
                 "ground_friction=0.3:1.3", "--window", "0.1", "--restarts", "1", "--evaluations", "12", "--json",
                 "--hold-out", str(folder / hold_out)]) == 0
    return json.loads(capsys.readouterr().out)


def test_a_fit_shows_its_progress_as_plain_lines_off_a_terminal(recordings, capsys):
    capsys.readouterr()
    assert main(["fit", "tetraspine-ntrt", str(recordings / "r1.npz"), "--engine", "mujoco", "--fit",
                 "ground_friction=0.3:1.3", "--window", "0.1", "--restarts", "2", "--evaluations", "12"]) == 0
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("fit: 0/24 losses (0 %)") or err[0].startswith("fit: 1/24 losses")
    assert err[-1].startswith("fit: 24/24 losses (100 %)") and err[-1].endswith("done")


def test_held_out_recording_never_enters_the_loss(recordings, capsys):
    a = _fit(recordings, "r2.npz", capsys)
    b = _fit(recordings, "r3.npz", capsys)
    assert a["restarts"] == b["restarts"] and a["constants"] == b["constants"]
    held = [r for r in a["recordings"].values() if r["held_out"]]
    assert len(held) == 1 and held[0]["before"]["window_error_cm"] > 0
    # held-out figures are reported, and they differ between the two hold-outs
    assert a["recordings"] != b["recordings"]


def test_constants_the_step_cannot_simulate_score_as_diverged_not_an_error(recordings):
    """The 3-segment Tetraspine's strings diverge above a 15.9 ms step (its stability estimate): a candidate at
    20 ms is scored DIVERGED_CM (100 cm), where the loss itself refuses it, and one at 1 ms as the loss does."""
    from spinefarm.protocol.errors import ConfigError
    from spinefarm.robot.trial_config import TrialConfig
    from spinefarm.worker.fit.loss import candidate_loss, fit_loss, prepare
    from spinefarm.worker.fit.readers import read_recording

    morph = load_morphology("tetraspine-ntrt")
    rec = [prepare("r1", read_recording(recordings / "r1.npz"), 0.1, 0.1)]
    unstable = TrialConfig(engine="mujoco", dt_s=0.02)
    with pytest.raises(ConfigError):
        fit_loss(morph, unstable, rec)
    assert candidate_loss(morph, unstable, rec) == 100.0
    stable = TrialConfig(engine="mujoco")
    assert candidate_loss(morph, stable, rec) == fit_loss(morph, stable, rec) < 100.0


def test_a_generation_in_processes_is_the_fit_in_one(recordings):
    """--jobs: the same candidates (CMA-ES asks a whole generation before any loss) and the same losses, so the
    same fit to the bit; the losses differ between candidates (the search was not flat)."""
    from spinefarm.robot.trial_config import TrialConfig
    from spinefarm.worker.fit.fitting import fit_constants
    from spinefarm.worker.fit.loss import prepare
    from spinefarm.worker.fit.readers import read_recording
    from spinefarm.worker.fit.search import parse_fit

    morph = load_morphology("tetraspine-ntrt")
    recs = [prepare(n, read_recording(recordings / f"{n}.npz"), 0.1, 0.2) for n in ("r1", "r2", "r3")]
    bounds = parse_fit("ground_friction=0.3:1.3,string_damping_n_s_per_m=5:20")
    one, two = (fit_constants(morph, TrialConfig(engine="mujoco"), recs, [], bounds, 1, 12, 0, None, jobs)
                for jobs in (1, 2))
    assert one["restarts"] == two["restarts"] and one["constants"] == two["constants"]
    assert one["loss"]["after"] < one["loss"]["before"]


def test_fit_recovers_constants_on_a_tiny_robot():
    morph = load_morphology("tetraspine-ntrt")
    true = {"ground_friction": 0.65, "string_stiffness_n_per_m": 1300.0}
    out = identify(morph, "mujoco", true, seeds=(3,), duration_s=0.6, window_s=0.1, restarts=1, evaluations=100)
    for name, c in out["constants"].items():
        assert c["true"] == true[name]
        assert c["rel_error"] <= 0.05 and c["identifiable"], (name, c)
    assert out["window_error_cm"]["after"] < out["window_error_cm"]["before"] / 5
    assert out["loss"]["after"] < out["loss"]["before"] / 5


@pytest.mark.parametrize(("fit", "robot", "message"), [
    ("friction", "tetraspine-ntrt", "unknown profile constant; received 'friction'"),
    ("ground_friction=0.05:2", "tetraspine-ntrt",
     "bounds outside its plausible range; received '0.05:2'; expected LO < HI within [0.1, 1.5]"),
    ("ground_friction", "tetrahedral-complex", "the recording does not fit tetrahedral-complex; received '3 segments'"),
])
def test_fit_refuses_bad_input_in_one_line(recordings, capsys, fit, robot, message):
    capsys.readouterr()
    assert main(["fit", robot, str(recordings / "r1.npz"), "--engine", "mujoco", "--fit", fit]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err


def test_a_pose_csv_fits_as_the_trial_record_does(recordings, capsys):
    """A user's motion-capture file is as good as our own recording: the same motion written as a pose CSV (metres,
    full precision, the rest lengths as columns) gives the same fit, bit for bit."""
    from spinefarm.worker.fit.readers import read_recording

    rec = read_recording(recordings / "r1.npz")
    nb, ns = rec.n_segments, rec.n_strings
    head = ["time_s"] + [f"seg{b}_{f}" for b in range(nb) for f in ("x_m", "y_m", "z_m", "qw", "qx", "qy", "qz")] \
        + [f"str{i}_rest_m" for i in range(ns)]
    cols = [rec.time_s[:, None]] + [np.concatenate([rec.position_m[:, b], rec.quat_wxyz[:, b]], axis=1)
                                    for b in range(nb)] + [rec.rest_length_m]
    csv_path = recordings / "mocap.csv"
    np.savetxt(csv_path, np.concatenate(cols, axis=1), delimiter=",", header=",".join(head), comments="", fmt="%.17g")
    out = []
    for path in (recordings / "r1.npz", csv_path):
        capsys.readouterr()
        assert main(["fit", "tetraspine-ntrt", str(path), "--engine", "mujoco", "--fit", "ground_friction=0.3:1.3",
                     "--window", "0.1", "--restarts", "1", "--evaluations", "6", "--json"]) == 0
        out.append(json.loads(capsys.readouterr().out))
    # the CSV holds no tensions: the loss is the pose error alone there, so compare what both fit on
    assert out[0]["window_error_cm"]["before"] == out[1]["window_error_cm"]["before"]
    assert out[0]["constants"]["ground_friction"]["fitted"] == pytest.approx(
        out[1]["constants"]["ground_friction"]["fitted"], rel=0.05)
