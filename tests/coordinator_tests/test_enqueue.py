"""`search --enqueue GAIT.json`: the user's parameter sets run first, exactly as given, the sampler goes on from
them (the paper's hill climbing from a gait found before), they are stored with the run and survive a resume;
a file that does not fit the run is refused before a run file exists."""

from __future__ import annotations

import json

import numpy as np
import pytest

from spinefarm.robot.spaces import param_space
from spinefarm.storage.hdf5_reader import Hdf5Reader
from tests.cli_tests.test_errors import one_line_error, run

pytestmark = pytest.mark.integration


def _gait(path, **values: float):
    path.write_text(json.dumps(values))
    return str(path)


def test_enqueued_sets_run_first_and_the_climb_starts_from_them(tmp_path):
    a = _gait(tmp_path / "a.json", x0=-0.5, x1=0.75, x2=-0.25)
    b = _gait(tmp_path / "b.json", x0=0.3125, x1=0.25, x2=0.28125)  # near the test objective's top (0.3): the best
    out = tmp_path / "run.h5"
    r = run("search", "sphere:3", "--enqueue", a, "--enqueue", b, "--sampler", "paper", "--startup-trials", "0",
            "--trials", "12", "--workers", "1", "--batch", "1", "--out", str(out), "--api-port", "-1", "--quiet")
    assert r.returncode == 0, r.stderr
    with Hdf5Reader(out) as s:
        cols = s.columns()
        assert [p.decode() for p in cols["phase"][:3]] == ["enqueued", "enqueued", "gaussian"]
        assert cols["params"][0].tolist() == [-0.5, 0.75, -0.25]
        assert cols["params"][1].tolist() == [0.3125, 0.25, 0.28125]
        assert np.all(cols["parent"][:2] == -1)
        climbed = cols["parent"][2:]
        assert np.all(climbed >= 0) and 1 in climbed.tolist()  # steps around the enqueued best
        assert len(s.run_meta().settings.enqueued) == 2
    r = run("search", "--resume", str(out), "--trials", "16", "--workers", "1", "--api-port", "-1", "--quiet")
    assert r.returncode == 0, r.stderr
    with Hdf5Reader(out) as s:
        cols = s.columns()
        assert s.n_trials() == 16 and sum(p == b"enqueued" for p in cols["phase"]) == 2
        assert cols["params"][1].tolist() == [0.3125, 0.25, 0.28125]


@pytest.mark.parametrize(("values", "extra", "needles"), [
    ({"x0": 0.1, "x1": 0.2}, (), ("do not match space", "missing ['x2']")),
    ({"x0": 0.1, "x1": 0.2, "x2": 3.0}, (), ("'x2' is outside its bounds", "3.0")),
    ({"x0": 0.1, "x1": 0.2, "x2": 0.3}, ("--trials", "1", "--enqueue"), ("more enqueued parameter sets than trials",)),
])
def test_a_file_that_does_not_fit_is_refused_before_a_run_file_exists(values, extra, needles, tmp_path):
    gait = _gait(tmp_path / "gait.json", **values)
    out = tmp_path / "r.h5"
    r = run("search", "sphere:3", "--enqueue", gait, *extra, *((gait,) if extra else ()), "--workers", "0",
            "--out", str(out), "--api-port", "-1", timeout=60)
    one_line_error(r, *needles)
    assert not out.exists()


def test_a_gait_of_another_controller_space_or_with_resume_is_refused(tmp_path):
    from tests.coordinator_tests.procs import ROOT

    gait = str(ROOT / "examples" / "gaits" / "tetraspine.json")  # the sidewinding space's
    out = tmp_path / "r.h5"
    r = run("search", "tetraspine", "--controller", "ntrt", "--enqueue", gait, "--engine", "bullet", "--workers",
            "0", "--out", str(out), "--api-port", "-1", timeout=60)
    one_line_error(r, "another controller space", "sidewinding", "ntrt")
    assert not out.exists()
    r = run("search", "--resume", str(out), "--enqueue", gait, timeout=60)
    one_line_error(r, "--resume", "--enqueue")


def test_a_gait_written_by_export_travels_to_the_bit():
    """Enqueued sets travel as unit-cube coordinates: a gait file written by `export --gait` (the shipped ones)
    comes back to the bit, so its trial runs the gait as written."""
    import argparse

    from spinefarm.cli.run_setup import enqueued
    from spinefarm.robot.morphology.registry import load_morphology
    from tests.coordinator_tests.procs import ROOT

    for name in ("tetraspine", "tetrahedral-complex", "ribbed"):
        path = ROOT / "examples" / "gaits" / f"{name}.json"
        gait = json.loads(path.read_text())
        args = argparse.Namespace(enqueue=[str(path)], morphology=name, controller=gait["controller"])
        (unit,) = enqueued(args)
        space = param_space(load_morphology(name), gait["controller"])
        assert space.from_unit(unit).tolist() == [gait["params"][n] for n in space.names], name
