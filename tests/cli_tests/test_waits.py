"""Every long wait shows its progress with an ETA (a line redrawn on a terminal, plain lines in a log), and a
search's options are checked before its calibration starts. Asserted by the messages' text."""

from __future__ import annotations

import io
import os
import pty
import subprocess
import sys

import pytest

from spinefarm.cli.waiting import SHOW_AFTER_S, Waiting, duration_text, progress_text
from tests.coordinator_tests.procs import ROOT

SMALL_CALIBRATION = ("--gaits", "4", "--search-trials", "0", "--bests", "0", "--duration", "0.5", "--settle", "0.2")
# 4 random gaits on MuJoCo, the same 4 judged on Bullet, up to 2 x 4 re-run at half the step
SMALL_CALIBRATION_TRIALS = 4 + 0 + 4 + 0 + 8


def spinefarm(*args: str, cwd, env: dict | None = None, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "spinefarm", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=600, env={**os.environ, "PYTHONPATH": str(ROOT), **(env or {})}, **kw)


def test_the_progress_text_names_the_count_the_time_spent_and_the_time_left():
    # 34 s for 12 of 98: 34 / 12 * 86 = 243.7 s left
    assert progress_text("calibration", "trials", 12, 98, 34.0) == (
        "calibration: 12/98 trials (12 %), 34 s elapsed, about 4 min 04 s left")
    assert progress_text("accuracy", "trials", 0, 40, 1.2) == (
        "accuracy: 0/40 trials (0 %), 1 s elapsed, estimating the time left")
    assert progress_text("fit", "windows", 7, 7, 3725.0) == "fit: 7/7 windows (100 %), 1 h 02 min elapsed, done"
    assert [duration_text(s) for s in (0.4, 59.6, 61, 3599, 7260)] == ["0 s", "1 min 00 s", "1 min 01 s",
                                                                      "59 min 59 s", "2 h 01 min"]


def test_a_log_gets_a_first_and_a_last_plain_line():
    out = io.StringIO()
    with Waiting("checking spine", "checks", stream=out, tty=False) as wait:
        for done in range(5):
            wait(done, 4)
    assert out.getvalue().splitlines() == ["checking spine: 0/4 checks (0 %), 0 s elapsed, estimating the time left",
                                           "checking spine: 4/4 checks (100 %), 0 s elapsed, done"]


def test_a_terminal_gets_one_line_redrawn_only_for_a_wait_longer_than_two_seconds():
    quick = io.StringIO()
    with Waiting("fit", "windows", stream=quick, tty=True) as wait:
        wait(0, 3)
        wait(3, 3)
    assert quick.getvalue() == ""  # over before SHOW_AFTER_S: nothing to see
    slow = io.StringIO()
    with Waiting("fit", "windows", stream=slow, tty=True) as wait:
        wait.start -= SHOW_AFTER_S + 8.0  # as if started 10 s ago
        wait(1, 3)
        wait(3, 3)
    text = slow.getvalue()
    assert text.startswith("\r\x1b[Kfit: 1/3 windows (33 %), 10 s elapsed, about 20 s left")
    assert text.endswith("\r\x1b[Kfit: 3/3 windows (100 %), 10 s elapsed, done\n") and text.count("\n") == 1


@pytest.mark.integration
def test_calibrate_shows_its_progress_in_a_log(tmp_path):
    n = SMALL_CALIBRATION_TRIALS
    r = spinefarm("calibrate", "tetraspine-ntrt", *SMALL_CALIBRATION, cwd=tmp_path,
                  env={"SPINEFARM_CACHE_DIR": str(tmp_path / "cache")})
    assert r.returncode == 0, r.stderr[-2000:]
    assert f"calibrating the tiers on tetraspine-ntrt: up to {n} trials on 2 processes" in r.stderr
    assert f"calibration: 0/{n} trials (0 %)" in r.stderr and "estimating the time left" in r.stderr
    assert f"calibration: {n}/{n} trials (100 %)" in r.stderr and r.stderr.rstrip().endswith("done")


@pytest.mark.integration
def test_calibrate_draws_one_line_on_a_terminal(tmp_path):
    n = SMALL_CALIBRATION_TRIALS
    main, sub = pty.openpty()
    t = subprocess.Popen([sys.executable, "-m", "spinefarm", "calibrate", "tetraspine-ntrt", *SMALL_CALIBRATION,
                          "--json"], cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=sub,
                         env={**os.environ, "PYTHONPATH": str(ROOT), "SPINEFARM_CACHE_DIR": str(tmp_path / "cache")})
    os.close(sub)
    seen = b""
    try:
        while chunk := os.read(main, 65536):  # read as it comes: a full pty would stop the command
            seen += chunk
    except OSError:  # EIO: the command has closed the terminal
        pass
    finally:
        os.close(main)
        t.wait(timeout=600)
    assert t.returncode == 0
    # redrawn in place (the calibration takes longer than SHOW_AFTER_S), no plain line of its start
    assert f"\r\x1b[Kcalibration: {n}/{n} trials (100 %)".encode() in seen, seen[-500:]
    assert f"calibration: 0/{n} trials (0 %)".encode() not in seen


SEARCH = ("search", "tetraspine-ntrt", "--trials", "2", "--workers", "1", "--duration", "0.3", "--api-port", "-1",
          "--no-verify", "--calibrate-gaits", "4", "--calibrate-search-trials", "0", "--calibrate-bests", "0",
          "--calibrate-duration", "0.3", "--calibrate-settle", "0.1")


@pytest.mark.integration
def test_a_bad_objective_or_scene_is_refused_before_the_calibration(tmp_path):
    env = {"SPINEFARM_CACHE_DIR": str(tmp_path / "cache")}
    bad = spinefarm(*SEARCH, "--objective", "fastest", "--out", str(tmp_path / "bad.h5"), cwd=tmp_path, env=env)
    assert bad.returncode == 2 and "unknown objective; received 'fastest'" in bad.stderr
    assert "calibrat" not in bad.stderr and not (tmp_path / "cache").exists() and not (tmp_path / "bad.h5").exists()
    scene = spinefarm(*SEARCH, "--scene", "moon", "--out", str(tmp_path / "bad.h5"), cwd=tmp_path, env=env)
    assert scene.returncode == 2 and "calibrat" not in scene.stderr and not (tmp_path / "cache").exists()


@pytest.mark.integration
@pytest.mark.parametrize("quiet", [False, True])
def test_a_search_shows_its_calibrations_progress_unless_quiet(tmp_path, quiet):
    env = {"SPINEFARM_CACHE_DIR": str(tmp_path / "cache")}
    r = spinefarm(*SEARCH, *(["--quiet"] if quiet else []), "--out", str(tmp_path / "ok.h5"), cwd=tmp_path, env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    n = 4 + 0 + 4 + 0 + 8  # from the search's --calibrate-* flags, as SMALL_CALIBRATION_TRIALS
    assert "engine auto: calibrating" in r.stderr
    if quiet:  # no progress line, the calibration's neither
        assert "calibration: " not in r.stderr
    else:
        assert f"calibration: 0/{n} trials (0 %)" in r.stderr and f"calibration: {n}/{n} trials (100 %)" in r.stderr


@pytest.mark.integration
def test_accuracy_and_check_show_their_progress(tmp_path):
    acc = spinefarm("accuracy", "tetraspine-ntrt", "--quick", "--seeds", "1", "--duration", "0.3", "--out",
                    str(tmp_path / "acc"), cwd=tmp_path)
    assert acc.returncode == 0, acc.stderr[-2000:]
    assert "accuracy: 0/" in acc.stderr and "estimating the time left" in acc.stderr
    last = [ln for ln in acc.stderr.splitlines() if ln.startswith("accuracy: ")][-1]
    done, total = last.split()[1].split("/")
    assert done == total and last.endswith("done")
    check = spinefarm("check", "tetraspine-ntrt", cwd=tmp_path)
    assert check.returncode == 0, check.stderr[-2000:]
    assert "checking tetraspine-ntrt: 0/4 checks (0 %)" in check.stderr
    assert "checking tetraspine-ntrt: 4/4 checks (100 %)" in check.stderr
