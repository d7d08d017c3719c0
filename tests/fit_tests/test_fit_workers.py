"""A fit's generations computed by the project's workers over real Zenoh: a router, two `spinefarm worker`
processes that find the fit's run as they find a search's, and the same fit to the bit as in one process."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from spinefarm.cli.local_workers import READY_ENV
from spinefarm.cli.main import main
from tests.coordinator_tests.helpers import free_endpoint, wait_for
from tests.coordinator_tests.procs import ROOT, stop


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    """Two short recordings of the 3-segment Tetraspine, made at two ground frictions (distinct motions)."""
    folder = tmp_path_factory.mktemp("recs")
    for seed, friction in ((1, 0.65), (2, 0.4)):
        (folder / f"p{seed}.yaml").write_text(f"constants: {{ground_friction: {friction}}}\n")
        assert main(["trial", "tetraspine-ntrt", "--random-seed", str(seed), "--duration", "0.3", "--engine",
                     "mujoco", "--record", str(folder / f"r{seed}.npz"), "--record-every", "0.001",
                     "--profile", str(folder / f"p{seed}.yaml"), "--json"]) in (0, 1)
    return folder


def _spinefarm(*args: str, ready: Path | None = None) -> subprocess.Popen:
    env = dict(os.environ, **({READY_ENV: str(ready)} if ready else {}))
    return subprocess.Popen([sys.executable, "-P", "-m", "spinefarm", *args], cwd=ROOT, text=True, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL if ready else subprocess.PIPE)


def _fit(folder, capsys, *extra: str) -> tuple[dict, str]:
    capsys.readouterr()
    assert main(["fit", "tetraspine-ntrt", str(folder / "r1.npz"), str(folder / "r2.npz"), "--engine", "mujoco",
                 "--fit", "ground_friction=0.3:1.3,string_damping_n_s_per_m=5:20", "--window", "0.1",
                 "--restarts", "1", "--evaluations", "12", "--json", *extra]) == 0
    out = capsys.readouterr()
    return json.loads(out.out), out.err


def test_workers_over_a_router_give_the_fit_of_one_process(recordings, capsys, tmp_path):
    ep = free_endpoint()
    router = _spinefarm("router", "--listen", ep)
    workers = []
    try:
        assert router.stdout.readline().startswith("router "), router.stderr.read()
        workers = [_spinefarm("worker", "--connect", ep, "--worker-id", f"w{i}", ready=tmp_path / f"w{i}")
                   for i in range(2)]
        wait_for(lambda: all((tmp_path / f"w{i}").exists() for i in range(2)), 60.0, 0.1, "both workers up")
        remote, err = _fit(recordings, capsys, "--connect", ep)
    finally:
        stop(*workers, router)
    local, _ = _fit(recordings, capsys)
    for key in ("restarts", "constants", "loss", "window_error_cm", "recordings"):
        assert remote[key] == local[key], key
    # the search moved (distinct losses), and both workers computed some of its 12 losses
    assert local["loss"]["after"] < local["loss"]["before"]
    counts = dict(item.rsplit(" ", 1) for item in err.split("fit losses by worker: ")[1].splitlines()[0].split(", "))
    assert set(counts) == {"w0", "w1"} and sum(int(n) for n in counts.values()) == 12, err


@pytest.mark.slow  # ~30 s: two worker processes start, each builds the run in its trial process
def test_local_workers_give_the_fit_of_one_process(recordings, capsys):
    """--workers 2: the fit starts its own two `spinefarm worker` processes on a loopback port and stops them."""
    remote, err = _fit(recordings, capsys, "--workers", "2")
    local, _ = _fit(recordings, capsys)
    for key in ("restarts", "constants", "loss", "recordings"):
        assert remote[key] == local[key], key
    counts = err.split("fit losses by worker: ")[1].splitlines()[0].split(", ")
    assert 1 <= len(counts) <= 2 and sum(int(c.rsplit(" ", 1)[1]) for c in counts) == 12, err


def test_workers_and_jobs_are_refused_together(recordings, capsys):
    capsys.readouterr()
    assert main(["fit", "tetraspine-ntrt", str(recordings / "r1.npz"), "--fit", "ground_friction", "--jobs", "2",
                 "--workers", "2"]) == 2
    err = capsys.readouterr().err.strip()
    assert "--jobs and --workers/--connect/--listen both say where" in err and "received '--jobs 2'" in err
    assert "\n" not in err


def _turned(quat_wxyz: np.ndarray, start: int, stop: int) -> np.ndarray:
    """The orientations turned about Y by an angle growing from 0 at row `start` to 270 degrees at `stop` (and
    kept after): a quaternion path whose two ends across that stretch point opposite ways (dot < 0)."""
    angle = np.clip((np.arange(len(quat_wxyz)) - start) / (stop - start), 0.0, 1.0) * 1.5 * np.pi
    w, y = np.cos(angle / 2)[:, None], np.sin(angle / 2)[:, None]
    q = quat_wxyz
    return np.stack([w * q[..., 0] - y * q[..., 2], w * q[..., 1] + y * q[..., 3], w * q[..., 2] + y * q[..., 0],
                     w * q[..., 3] - y * q[..., 1]], axis=-1)


@pytest.mark.parametrize(("engine", "turn"), [("mujoco", False), ("bullet", False), ("mujoco", True)])
def test_a_cut_recording_gives_the_losses_of_the_whole(engine, turn):
    """What a fit run sends of NTRT's published Tetraspine run (2 s, a 0.2 s window a second): the rows no window
    reads replaced by copies (far smaller), and the windows' errors, tensions included, the same to the bit; also
    when the segments turn by 270 degrees between two windows (the quaternions' signs across the cut disagree)."""
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.robot.trial_config import TrialConfig
    from spinefarm.worker.fit.loss import prepare, squared_errors
    from spinefarm.worker.fit.readers import read_recording
    from spinefarm.worker.fit.task import _array, _prepared, _recording, _sent

    rec = read_recording(Path("/work/shared/ntrt-recordings/TetraSpine/published"))
    n = int(np.searchsorted(rec.time_s, rec.time_s[0] + 2.0 + 1e-9))
    cut = {f: getattr(rec, f)[:n] for f in ("time_s", "position_m", "quat_wxyz", "string_length_m",
                                            "rest_length_m", "tension_n")}
    if turn:
        cut["quat_wxyz"] = _turned(cut["quat_wxyz"], 30, 90)
    p = prepare("published", dataclasses.replace(rec, **cut), 0.2, 1.0)
    sent = _sent(p.rec, p.windows)
    assert sent is not p.rec and len(_array(sent.position_m)["f8z"]) < len(_array(p.rec.position_m)["f8z"]) / 3
    morph, cfg = load_morphology("tetraspine-ntrt2026"), TrialConfig(engine=engine)
    here = squared_errors(morph, cfg, p, True)
    there = squared_errors(morph, cfg, _prepared(json.loads(json.dumps(_recording(p)))), True)
    assert here.tobytes() == there.tobytes() and here.max() > 0


def test_a_fit_run_config_round_trips_and_a_bad_one_is_refused(recordings):
    """The run's config carries the fit through JSON with its hash; a plain run's config has no `fit` key (its hash
    as before); a malformed `fit` is refused in one line naming it."""
    from spinefarm.protocol.errors import MessageError
    from spinefarm.protocol.run import RunConfig
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.robot.trial_config import TrialConfig
    from spinefarm.worker.fit.loss import prepare
    from spinefarm.worker.fit.readers import read_recording
    from spinefarm.worker.fit.search import parse_fit
    from spinefarm.worker.fit.task import fit_run_config

    p = prepare("r1", read_recording(recordings / "r1.npz"), 0.1, 0.1)
    config = fit_run_config("fit-x", load_morphology("tetraspine-ntrt"), TrialConfig(engine="mujoco"), [p],
                            parse_fit("ground_friction"))
    back = RunConfig.from_dict(json.loads(json.dumps(config.to_dict())))
    assert back == config and back.config_hash() == config.config_hash()
    plain = RunConfig.from_dict({k: v for k, v in config.to_dict().items() if k != "fit"})
    assert "fit" not in plain.to_dict() and plain.config_hash() != config.config_hash()
    with pytest.raises(MessageError) as bad:
        RunConfig.from_dict({**config.to_dict(), "fit": {"recordings": "r1.npz"}})
    assert "run config field 'fit' is malformed" in str(bad.value) and "\n" not in str(bad.value)
