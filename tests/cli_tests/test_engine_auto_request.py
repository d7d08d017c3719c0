"""What `--engine auto` asks its calibration for when no shipped one answers (docs/engines.md, "Fitting the
screen to the judge"): a user's robot may have its screen fitted within `--calibrate-fit-screen N` losses
(default 40), a built-in never; the calibration runs on one process per local worker, at most two (the
shipped calibrations' two processes). The calibration itself is replaced by a shipped result so no child
runs: what is checked is the request."""

from __future__ import annotations

import json

import pytest

from spinefarm.cli import engine_auto
from spinefarm.cli.main import build_parser
from spinefarm.worker.tools import shipped_calibration
from tests.worker_tests.test_specfile import GOOD


@pytest.fixture
def asked(tmp_path, monkeypatch) -> list[tuple[str, int, int]]:
    """(robot, processes, fit budget) of each calibration asked for; none is shipped."""
    result = json.loads(shipped_calibration.shipped_path("tetraspine").read_text())
    monkeypatch.setattr(shipped_calibration, "SHIPPED_DIR", tmp_path / "none-shipped")
    calls: list[tuple[str, int, int]] = []

    def calibrate(morphology, settings, fit_evaluations=0, quiet=False):
        calls.append((morphology, settings.jobs, fit_evaluations))
        return result, False

    monkeypatch.setattr(engine_auto, "calibrate_in_child", calibrate)
    return calls


def _choose(*argv: str) -> None:
    engine_auto.choose_engine(build_parser().parse_args(["search", *argv]))


def test_a_builtin_is_never_fitted_and_a_users_robot_within_its_budget(asked, tmp_path) -> None:
    spec = tmp_path / "chain.yaml"
    spec.write_text(GOOD)
    _choose("tetraspine", "--calibrate-fit-screen", "7")
    _choose(str(spec), "--calibrate-fit-screen", "7")
    _choose(str(spec))
    assert [fit for _, _, fit in asked] == [0, 7, 40]


@pytest.mark.parametrize(("workers", "processes"), [("0", 1), ("1", 1), ("2", 2), ("5", 2)])
def test_the_calibration_runs_on_a_process_per_local_worker_at_most_two(asked, workers, processes) -> None:
    _choose("tetraspine", "--workers", workers)
    assert asked == [("tetraspine", processes, 0)]


def test_a_calibration_that_cannot_run_falls_back_to_the_default_engine_and_says_why(tmp_path, monkeypatch,
                                                                                      capsys) -> None:
    from spinefarm.protocol.errors import ConfigError

    monkeypatch.setattr(shipped_calibration, "SHIPPED_DIR", tmp_path / "none-shipped")

    def cannot(*_args, **_kw):
        raise ConfigError("no default step simulates this robot")

    monkeypatch.setattr(engine_auto, "calibrate_in_child", cannot)
    args = build_parser().parse_args(["search", "tetraspine"])
    assert engine_auto.choose_engine(args) is None
    assert args.engine is None  # not given: the run's default engine, Bullet
    assert "the calibration could not run (no default step simulates this robot); bullet" in capsys.readouterr().err


def test_a_shipped_calibration_is_stored_as_shipped_and_a_fresh_one_is_not(asked, tmp_path, monkeypatch) -> None:
    fresh = engine_auto.choose_engine(build_parser().parse_args(["search", "tetraspine"]))
    assert (fresh.cached, fresh.shipped) == (False, False)
    monkeypatch.undo()  # the package's shipped calibrations again
    found = engine_auto.choose_engine(build_parser().parse_args(["search", "tetraspine"]))
    assert (found.cached, found.shipped) == (True, True) and "[shipped calibration]" in found.describe()
