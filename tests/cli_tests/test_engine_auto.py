"""`--engine auto`'s pieces that need no calibration (docs/engines.md): the rungs it screens with, a sixth of
the trial, a third and the whole of it (docs/performance.md's ladder table), and when it is asked for (search's
default) or not."""

from __future__ import annotations

import argparse

from spinefarm.cli.engine_auto import choose_engine, wants_auto
from spinefarm.robot.morphology.specladder import DEFAULT_LADDER


def test_the_default_rungs_are_a_sixth_a_third_of_the_trial_and_the_whole():
    assert DEFAULT_LADDER.rungs(30.0) == "5,10,30" and DEFAULT_LADDER.eta == 4
    assert DEFAULT_LADDER.rungs(5.0) == "0.833333,1.66667,5"


def _args(**kw) -> argparse.Namespace:
    base = dict(engine=None, engine_default="auto", resume=None, morphology="tetraspine", controller=None)
    return argparse.Namespace(**{**base, **kw})


def test_auto_is_asked_for_by_name_or_as_the_default():
    assert wants_auto(_args()) and wants_auto(_args(engine="auto", engine_default=None))
    assert not wants_auto(_args(engine="bullet")) and not wants_auto(_args(engine_default=None))


def test_a_resume_or_a_test_objective_is_not_calibrated():
    # a resumed run keeps the engine its file says; a test objective simulates nothing: neither calibrates
    resumed = _args(engine="auto", resume="run.h5")
    assert choose_engine(resumed) is None and resumed.engine is None
    sphere = _args(engine="auto", morphology="sphere:3")
    assert choose_engine(sphere) is None and sphere.engine is None
    given = _args(engine="mujoco", engine_default=None)
    assert choose_engine(given) is None and given.engine == "mujoco"


def _shipped(tmp_path, monkeypatch, decision: str) -> None:
    """tetraspine's shipped calibration, its decision set by hand, as the only shipped file."""
    import json

    from spinefarm.worker.tools import shipped_calibration

    result = json.loads(shipped_calibration.shipped_path("tetraspine").read_text())
    (tmp_path / "tetraspine.json").write_text(json.dumps({**result, "decision": decision}))
    monkeypatch.setattr(shipped_calibration, "SHIPPED_DIR", tmp_path)


def _search(*argv: str) -> argparse.Namespace:
    from spinefarm.cli.main import build_parser

    return build_parser().parse_args(["search", "tetraspine", *argv])


def test_a_mujoco_decision_screens_on_mujoco_over_a_sixth_a_third_and_the_whole(tmp_path, monkeypatch):
    _shipped(tmp_path, monkeypatch, "mujoco")
    args = _search()                         # tetraspine's trial: 30 s
    choice = choose_engine(args)
    assert (args.engine, args.rungs, args.eta) == ("mujoco", "5,10,30", 4)
    assert (choice.engine, choice.cached, choice.rungs_added, choice.eta_added) == ("mujoco", True, "5,10,30", 4)
    args = _search("--duration", "12")
    assert choose_engine(args).rungs_added == "2,4,12" and args.rungs == "2,4,12"
    args = _search("--rungs", "1,3")         # the user's rungs are kept
    assert choose_engine(args).rungs_added is None and args.rungs == "1,3"


def test_a_bullet_decision_screens_nothing(tmp_path, monkeypatch):
    _shipped(tmp_path, monkeypatch, "bullet")
    args = _search()
    choice = choose_engine(args)
    assert (args.engine, args.rungs, choice.engine, choice.rungs_added) == ("bullet", None, "bullet", None)
