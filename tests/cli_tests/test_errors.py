"""Every ordinary mistake ends in one clear line on stderr, no traceback, a non-zero exit, nothing left behind."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.coordinator_tests.helpers import wait_for
from tests.coordinator_tests.procs import ROOT


def run(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "spinefarm", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=timeout)


def one_line_error(r: subprocess.CompletedProcess, *needles: str) -> None:
    assert r.returncode != 0, r.stdout
    assert "Traceback" not in r.stderr, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if "error:" in ln]
    assert len(lines) == 1, r.stderr
    for n in needles:
        assert n in lines[0], r.stderr


@pytest.fixture(scope="module")
def sphere_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "sphere.h5"
    r = run("search", "sphere:3", "--trials", "1500", "--workers", "1", "--out", str(out), "--api-port", "-1",
            "--quiet")
    assert r.returncode == 0, r.stderr
    return out


@pytest.fixture
def a_file(tmp_path):
    f = tmp_path / "plain-file"
    f.write_text("x")
    return f


@pytest.mark.parametrize("case", ["search-out", "search-out-ext", "trial-record", "trial-record-ext",
                                  "render-out", "render-out-ext", "export-csv", "export-csv-ext"])
def test_an_output_path_that_cannot_be_written_or_has_the_wrong_extension(case, a_file, tmp_path, sphere_run):
    bad_dir = a_file / "sub"  # a path below a plain file can never be created
    args = {
        "search-out": ("search", "sphere:3", "--workers", "0", "--api-port", "-1", "--out", str(bad_dir / "r.h5")),
        "search-out-ext": ("search", "sphere:3", "--workers", "0", "--api-port", "-1", "--out",
                           str(tmp_path / "r.csv")),
        "trial-record": ("trial", "tetraspine", "--duration", "0.1", "--record", str(bad_dir / "t.npz")),
        "trial-record-ext": ("trial", "tetraspine", "--duration", "0.1", "--record", str(tmp_path / "t.json")),
        "render-out": ("render", "tetraspine", "--out", str(bad_dir / "s.png")),
        "render-out-ext": ("render", "tetraspine", "--out", str(tmp_path / "s.txt")),
        "export-csv": ("export", str(sphere_run), "--csv", str(bad_dir / "x.csv")),
        "export-csv-ext": ("export", str(sphere_run), "--csv", str(tmp_path / "x.h5")),
    }[case]
    r = run(*args)
    one_line_error(r, "received")
    assert ("wrong extension" in r.stderr) == case.endswith("-ext"), r.stderr
    assert not list(tmp_path.glob("r.*")) and not list(tmp_path.glob("s.*")) and not list(tmp_path.glob("t.*"))


def test_export_csv_into_a_pipe_closed_early_is_quiet(sphere_run):
    p = subprocess.Popen([sys.executable, "-m", "spinefarm", "export", str(sphere_run), "--csv"], cwd=ROOT,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert p.stdout.readline().startswith("trial_id,")
    p.stdout.close()  # as `| head -1` does
    err = p.stderr.read()
    assert p.wait(30) != 0
    assert "Traceback" not in err and "BrokenPipe" not in err, err


@pytest.mark.parametrize(("flag", "value", "command"), [
    ("--listen", "tcp/127.0.0.1", "search"), ("--listen", "127.0.0.1:7447", "coordinator"),
    ("--connect", "tcp/localhost:99999", "search"), ("--connect", "tcp:/host:7447", "worker"),
])
def test_a_malformed_endpoint_is_refused_before_a_run_file_exists(flag, value, command, tmp_path):
    out = tmp_path / "r.h5"
    args = ("worker", flag, value) if command == "worker" else (
        command, "sphere:3", "--trials", "5", "--out", str(out), flag, value, "--api-port", "-1",
        *(("--workers", "0") if command == "search" else ()))
    r = run(*args, timeout=30)
    one_line_error(r, flag, value)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("port", ["70000", "-5", "0"])
def test_api_port_out_of_range_is_refused_at_once(port, tmp_path):
    r = run("search", "sphere:3", "--workers", "0", "--api-port", port, "--out", str(tmp_path / "r.h5"),
            timeout=20)
    one_line_error(r, "--api-port", port)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(("flag", "value"), [("--judge-drift", "0"), ("--judge-drift", "nan"),
                                             ("--judge-drift", "11"), ("--verify-tolerance", "-1"),
                                             ("--judge-share", "0"), ("--judge-share", "1.5")])
def test_judge_settings_out_of_range_are_refused_before_a_run_file_exists(flag, value, tmp_path):
    r = run("search", "sphere:3", "--workers", "0", flag, value, "--out", str(tmp_path / "r.h5"), timeout=20)
    one_line_error(r, flag, value)
    assert list(tmp_path.iterdir()) == []


def test_api_port_of_the_api_command_out_of_range(tmp_path):
    one_line_error(run("api", "x.h5", "--port", "65536", timeout=20), "--port", "65536")


def test_accuracy_with_zero_seeds():
    one_line_error(run("accuracy", "tetraspine", "--quick", "--seeds", "0", timeout=30), "--seeds", "0")


def test_search_without_workers_says_how_to_attach_them(tmp_path):
    out = tmp_path / "r.h5"
    p = subprocess.Popen([sys.executable, "-m", "spinefarm", "search", "sphere:3", "--trials", "5", "--workers", "0",
                          "--out", str(out), "--api-port", "-1", "--quiet"], cwd=ROOT, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    try:
        lines = [p.stderr.readline() for _ in range(3)]
    finally:
        p.send_signal(signal.SIGINT)
        p.communicate(timeout=30)
    hint = next(ln for ln in lines if "no local workers" in ln)
    assert "spinefarm worker --connect tcp/127.0.0.1:" in hint and "--run " in hint


def test_a_worker_that_cannot_reach_its_coordinator_says_so_within_seconds():
    p = subprocess.Popen([sys.executable, "-m", "spinefarm", "worker", "--connect", "tcp/127.0.0.1:9"], cwd=ROOT,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    t0 = time.monotonic()
    try:
        line = p.stderr.readline()
        said_at = time.monotonic() - t0
    finally:
        p.send_signal(signal.SIGINT)
        _, rest = p.communicate(timeout=30)
    assert "cannot reach a coordinator at tcp/127.0.0.1:9" in line, line + rest
    assert said_at < 8.0
    assert p.returncode == 0, rest


def test_ctrl_c_stops_a_worker_whose_coordinator_accepts_tcp_but_never_answers():
    """zenoh.open waits on a handshake that never comes; Ctrl-C still stops the worker at once."""
    import socket

    with socket.socket() as silent:
        silent.bind(("127.0.0.1", 0))
        silent.listen(16)
        port = silent.getsockname()[1]
        p = subprocess.Popen([sys.executable, "-m", "spinefarm", "worker", "--connect", f"tcp/127.0.0.1:{port}"],
                             cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            line = p.stderr.readline()  # it says it is trying
        finally:
            p.send_signal(signal.SIGINT)
            t0 = time.monotonic()
            _, rest = p.communicate(timeout=30)
    assert f"tcp/127.0.0.1:{port} accepts connections but no Zenoh session has answered" in line \
        or f"refused by tcp/127.0.0.1:{port}" in line, line + rest
    assert p.returncode == 0, rest
    assert time.monotonic() - t0 < 5.0


def test_api_says_which_files_it_skips_and_why(sphere_run, tmp_path, a_file):
    p = subprocess.Popen([sys.executable, "-X", "faulthandler", "-m", "spinefarm", "api", str(sphere_run),
                          str(tmp_path / "gone.h5"),
                          str(a_file), "--port", "18731"], cwd=ROOT, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    try:
        lines = [p.stderr.readline() for _ in range(3)]
    finally:
        p.send_signal(signal.SIGINT)
        try:
            p.communicate(timeout=60)  # Ctrl-C stops it (well within this on a loaded machine)
        except subprocess.TimeoutExpired:
            p.send_signal(signal.SIGABRT)  # faulthandler prints where every thread stands
            _, rest = p.communicate()
            pytest.fail(f"spinefarm api did not stop within 60 s of Ctrl-C; it printed: {rest[-6000:]}")
    assert f"skipping {tmp_path / 'gone.h5'}: no such file" in lines[0]
    assert f"skipping {a_file}: cannot open run file" in lines[1]
    assert "dashboard on http://127.0.0.1:18731/ (1 file(s))" in lines[2]
    one_line_error(run("api", str(a_file), timeout=20), "none of the given run files")


@pytest.mark.integration
def test_ctrl_c_while_the_best_is_re_simulated(tmp_path):
    out = tmp_path / "r.h5"
    p = subprocess.Popen([sys.executable, "-m", "spinefarm", "search", "tetraspine", "--trials", "1", "--workers",
                          "1", "--duration", "3", "--out", str(out), "--api-port", "-1", "--engine", "bullet"],
                         cwd=ROOT,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    err = []
    for line in p.stderr:
        err.append(line)
        if "the judge re-simulates the best" in line:
            break
    time.sleep(1.0)
    t0 = time.monotonic()
    os.killpg(p.pid, signal.SIGINT)  # what Ctrl-C in a terminal does: the whole process group
    stdout, rest = p.communicate(timeout=30)
    stderr = "".join(err) + rest
    assert time.monotonic() - t0 < 10.0
    assert p.returncode == 130, stderr
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr, stderr
    assert "the best is reported unverified" in stderr
    assert "best trial 0" in stdout
    from spinefarm.storage.hdf5_reader import read_run

    _, cols = read_run(out)
    assert cols["status"].tolist() == [b"complete"]


@pytest.mark.parametrize(("args", "needles"), [
    (("trial",), ("no robot to run", "--run")),
    (("trial", "tetraspine", "--trial-id", "3"), ("--trial-id needs --run",)),
    (("trial", "--run", "missing.h5"), ("missing.h5",)),
])
def test_a_trial_without_a_robot_or_with_a_stray_trial_id(args, needles):
    one_line_error(run(*args, timeout=30), *needles)


def test_a_trial_of_a_run_names_no_robot_of_its_own(sphere_run):
    one_line_error(run("trial", "tetraspine", "--run", str(sphere_run), timeout=30), "--run names its own robot")


@pytest.mark.parametrize("args", [("trial", "tetraspine", "--seed", "-1", "--duration", "0.1"),
                                  ("trial", "tetraspine", "--random-seed", "-2", "--duration", "0.1"),
                                  ("render", "tetraspine", "--random-seed", "-3"),
                                  ("search", "sphere:2", "--seed", "-1", "--workers", "0", "--api-port", "-1")])
def test_a_negative_seed_is_refused_by_name(args, tmp_path):
    out = ("--out", str(tmp_path / "r.h5")) if args[0] == "search" else ()
    one_line_error(run(*args, *out, timeout=60), "seed is a whole number >= 0", "received -")
    assert not (tmp_path / "r.h5").exists()


def test_a_parameter_file_that_is_no_text_is_refused_by_name(tmp_path):
    binary = tmp_path / "gait.json"
    binary.write_bytes(b"\x89HDF\r\n\x1a\n\xff\xfe")
    one_line_error(run("trial", "tetraspine", "--params", str(binary), timeout=60), "cannot be read as text",
                   "gait.json")
    one_line_error(run("trial", "tetraspine", "--params", str(tmp_path), timeout=60), "cannot be read as text")


@pytest.mark.parametrize("flag", [("--trials", "0"), ("--duration", "-1"), ("--eta", "1"), ("--lease", "0"),
                                  ("--rungs", "3,2")])
def test_search_flags_are_checked_before_the_engine_calibration(flag, tmp_path):
    """`--engine auto` calibrates an uncached robot for minutes: a mistyped flag must not wait for that."""
    spec = tmp_path / "fresh.yaml"
    spec.write_text(run("spec", "tetraspine-ntrt", "--name", f"fresh-{os.getpid()}-{flag[0][2:]}").stdout)
    r = run("search", str(spec), *flag, "--workers", "0", "--api-port", "-1", "--out", str(tmp_path / "r.h5"),
            timeout=60)
    words = {"--rungs": ("rungs must be increasing",)}
    one_line_error(r, *words.get(flag[0], (flag[0].lstrip("-"), "out of range")))
    assert "calibrating" not in r.stderr and not (tmp_path / "r.h5").exists()


def _children(pid: int) -> list[int]:
    out: list[int] = []
    for task in (Path("/proc") / str(pid) / "task").iterdir():
        out += [int(c) for c in (task / "children").read_text().split()]
    return out


def test_a_search_killed_while_it_calibrates_leaves_no_calibration_running(tmp_path):
    """The calibration of `--engine auto` runs in its own process: it must stop with the search, even a
    SIGKILLed one, instead of computing on alone for minutes."""
    spec = tmp_path / "fresh.yaml"
    spec.write_text(run("spec", "tetraspine-ntrt", "--name", f"orphan-{os.getpid()}").stdout)
    search = subprocess.Popen([sys.executable, "-m", "spinefarm", "search", str(spec), "--workers", "0",
                               "--api-port", "-1", "--out", str(tmp_path / "r.h5")], cwd=ROOT,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        calibration = wait_for(lambda: _children(search.pid), timeout_s=60, poll_s=0.1, what="the calibration")[0]
    finally:
        search.kill()
        search.wait(10)
    wait_for(lambda: not Path(f"/proc/{calibration}").exists() or "Z" in
             Path(f"/proc/{calibration}/stat").read_text().split(")")[-1].split()[:1],
             timeout_s=30, poll_s=0.1, what="the calibration process to stop")


def test_a_spec_file_that_is_no_text_is_refused_by_name(tmp_path):
    binary = tmp_path / "robot.yaml"
    binary.write_bytes(b"\xff\xfe\x00robot")
    one_line_error(run("trial", str(binary), "--duration", "0.1", timeout=60), "cannot read the spec file",
                   "robot.yaml")
    child = tmp_path / "child.yaml"
    child.write_text(f"base: {binary}\nname: child\n")
    one_line_error(run("check", str(child), timeout=60), "field base: cannot read the spec to start from")


def test_a_coordinator_that_cannot_listen_leaves_no_run_file(tmp_path):
    """The port is taken: one line, and the run file it had just made is gone, so the same command works once
    the port is free (it said "run file already exists")."""
    import socket

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        out = tmp_path / "r.h5"
        r = run("coordinator", "sphere:2", "--listen", f"tcp/127.0.0.1:{port}", "--out", str(out), "--api-port",
                "-1", timeout=60)
    one_line_error(r, "cannot open the Zenoh session", "Address already in use")
    assert not out.exists() and not Path(str(out) + ".status.json").exists()
