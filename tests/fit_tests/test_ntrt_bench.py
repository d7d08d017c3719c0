"""bench/fit.py --ntrt: which of NTRT's recordings it fits (the published run and the draws NTRT ran to the end,
as their run-info.json says) and how far into each (--span), and that it fits only constants with a plausible
range."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from spinefarm.worker.fit.search import parse_fit
from tests.coordinator_tests.procs import ROOT

NTRT = Path("/work/shared/ntrt-recordings")


def _bench():
    spec = importlib.util.spec_from_file_location("fit_bench", ROOT / "bench" / "fit.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_aborted_draws_left_out():
    bench = _bench()
    aborted = {d.name for d in (NTRT / "Ribbed").iterdir() if d.is_dir() and any(
        r.get("aborted") for r in json.loads((d / "run-info.json").read_text())["runs"].values())}
    assert aborted == {"random-00", "random-02"}  # NTRT's own run-info, read here without the bench
    kept = [d.name for d in sorted((NTRT / "Ribbed").iterdir()) if d.is_dir() and bench._full(d)]
    assert kept == ["published", "random-01", "random-03", "random-08", "random-09"]


def test_published_and_draws_cut_to_the_span():
    recs = _bench().ntrt_recordings(NTRT / "TetraSpine", 0.2, 0.5, 1.0)
    assert [p.name for p in recs] == ["published", "random-00", "random-01", "random-02", "random-03"]
    for p in recs:
        # NTRT samples every 10 ms from t = 0: 1 s is 101 rows; windows of 0.2 s start at 0 and 0.5 s
        assert len(p.rec.time_s) == 101 and np.isclose(p.rec.time_s[-1] - p.rec.time_s[0], 1.0)
        assert p.rec.tension_n.shape[0] == p.rec.rest_length_m.shape[0] == p.poses.shape[0] == 101
        assert [w.start for w in p.windows] == [0, 50] and [len(w.rows) for w in p.windows] == [20, 20]


def test_fitted_constants_have_plausible_ranges():
    bench = _bench()
    assert set(bench.NTRT_FOLDERS) == {"tetraspine-ntrt2026", "tetrahedral-complex-ntrt2026",
                                       "octahedral-complex-ntrt2026", "ribbed-ntrt2026"}
    for engine, names in bench.NTRT_FIT.items():
        bounds = parse_fit(names)  # refuses a name without a documented range
        assert {b.name for b in bounds} >= {"ground_friction", "string_damping_n_s_per_m"}
        assert all(not b.name.startswith(("mujoco.", "bullet.")) or b.name.startswith(engine) for b in bounds)


def test_scan_reports_each_recording_and_their_rms():
    """--scan: per value, every recording's window error and all of them together (the RMS over equal windows:
    each recording here has one 0.2 s window); NTRT's friction 0.5 is the model's, so its row is the model's."""
    import argparse

    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.robot.trial_config import TrialConfig
    from spinefarm.worker.fit.loss import window_error_cm

    args = argparse.Namespace(spines=["tetraspine-ntrt2026"], engines=["mujoco"], recordings=str(NTRT),
                              window=0.2, stride=1.0, span=0.4, scan="ground_friction=0.5,0.3", no_replay=True)
    out = _bench().scan_bench(args)["spines"]["tetraspine-ntrt2026"]["mujoco"]
    rows = out["window_error_cm"]
    assert list(rows) == ["0.5", "0.3"] and out["replay_ratio"] == {}
    for row in rows.values():
        per = [v for k, v in row.items() if k != "all"]
        assert len(per) == 5 and row["all"] == pytest.approx(np.sqrt(np.mean(np.square(per))), rel=1e-12)
    assert rows["0.5"] != rows["0.3"]
    recs = _bench().ntrt_recordings(NTRT / "TetraSpine", 0.2, 1.0, 0.4)
    plain = window_error_cm(load_morphology("tetraspine-ntrt2026"), TrialConfig(engine="mujoco"), recs[:1])
    assert rows["0.5"]["published"] == plain


def test_precision_is_read_from_the_build():
    """The installed pybullet wheel is built with BT_USE_DOUBLE_PRECISION (its setup.py): 1 + 2^-40 survives."""
    assert _bench().bullet_precision() == "double"


def test_the_jitter_shifts_each_segments_start_and_keeps_the_recorded_poses():
    bench = _bench()
    p = bench.ntrt_recordings(NTRT / "TetraSpine", 0.2, 1.0, 0.4)[0]
    assert bench._jittered(p, 0) is p
    q = bench._jittered(p, 1)
    shift_cm = (q.rec.position_m - p.rec.position_m) * 100
    assert np.allclose(shift_cm, shift_cm[:1], rtol=0, atol=1e-12)  # one offset a segment: velocities unchanged
    assert 1e-8 < np.abs(shift_cm).max() < 1e-5  # the size of a 1e-6 cm Gaussian over 9 numbers
    assert q.poses is p.poses  # still checked against the recorded poses


def test_measure_reports_the_window_error_over_every_window():
    """--measure: the RMS over the windows of their pose error is loss.window_error_cm's (windows of equal size),
    and a 1e-6 cm jitter of the start moves it, by far less than 1 %."""
    import argparse

    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.robot.trial_config import TrialConfig
    from spinefarm.worker.fit.loss import window_error_cm

    def measure(seed: int) -> dict:
        args = argparse.Namespace(spines=["tetraspine-ntrt2026"], recordings=str(NTRT), window=0.2, stride=1.0,
                                  span=0.4, early=1.0, no_replay=True, replay_duration=None, jitter_seed=seed,
                                  engine_option=["friction_anchor=false"])
        return _bench().measure_bench(args)

    out = measure(0)
    assert out["precision"] == "double" and out["engine_options"] == {"friction_anchor": False}
    row = out["spines"]["tetraspine-ntrt2026"]
    recs = _bench().ntrt_recordings(NTRT / "TetraSpine", 0.2, 1.0, 0.4)
    cfg = TrialConfig(engine="bullet", engine_options={"friction_anchor": False})
    assert row["windows"] == 5 and row["replay_ratio"] is None
    assert row["window_error_cm"] == pytest.approx(window_error_cm(load_morphology("tetraspine-ntrt2026"), cfg, recs),
                                                   rel=1e-12)
    jittered = measure(1)["spines"]["tetraspine-ntrt2026"]["window_error_cm"]
    assert jittered != row["window_error_cm"] and jittered == pytest.approx(row["window_error_cm"], rel=0.01)
