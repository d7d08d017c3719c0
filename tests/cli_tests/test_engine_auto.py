"""`--engine auto`'s pieces that need no calibration (docs/engines.md): the rungs it screens with, a sixth of
the trial, a third and the whole of it (docs/performance.md's ladder table), and when it is asked for (search's
default) or not."""

from __future__ import annotations

import argparse

from spinefarm.cli.engine_auto import choose_engine, default_rungs, wants_auto


def test_the_default_rungs_are_a_sixth_a_third_of_the_trial_and_the_whole():
    assert default_rungs(30.0) == "5,10,30"
    assert default_rungs(5.0) == "0.833333,1.66667,5"


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
