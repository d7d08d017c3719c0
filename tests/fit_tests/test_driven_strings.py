"""NTRT records its muscles only (the CPG-driven strings), not the octahedral complex's ligaments or the ribbed
spine's intercostals: such a recording's string columns are the robot's driven strings in order, and the
passive strings keep the model's own rest length in a window."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.fit.readers import read_recording
from spinefarm.worker.fit.recording import RecordingError
from spinefarm.worker.fit.windows import Window, driven_strings, run_windows
from spinefarm.worker.trial.setup import TrialSetup

NTRT = Path("/work/shared/ntrt-recordings")
OCTA = NTRT / "OctahedralComplex" / "published"


@pytest.mark.skipif(not OCTA.exists(), reason="NTRT's recordings are not on this machine")
@pytest.mark.parametrize("spine, folder", [("octahedral-complex-ntrt2026", "OctahedralComplex"),
                                           ("ribbed-ntrt2026", "Ribbed")])
def test_recorded_strings_are_the_driven_ones_in_ntrt_order(spine, folder):
    morph = load_morphology(spine)
    rec = read_recording(NTRT / folder / "published")
    n = len(morph.structure.strings)
    recorded = rec.check_robot(rec.n_segments, n, spine, driven_strings(morph))
    assert rec.n_strings < n and len(recorded) == rec.n_strings
    # NTRT's own start lengths of its muscles (model-meta.txt), in its order, are our driven strings' ones
    meta = (NTRT / folder / "published" / "model-meta.txt").read_text()
    ntrt_cm = np.array([float(x) for x in re.findall(r"start_length=(\S+)", meta)])
    ours_cm = TrialSetup(morph, TrialConfig(engine="mujoco"), None).geom.start_length_cm[recorded]
    assert np.max(np.abs(ours_cm - ntrt_cm)) < 1e-6


@pytest.mark.skipif(not OCTA.exists(), reason="NTRT's recordings are not on this machine")
def test_other_string_counts_refused_naming_both():
    morph = load_morphology("octahedral-complex-ntrt2026")
    rec = read_recording(OCTA)
    with pytest.raises(RecordingError) as err:
        rec.check_robot(12, 90, "octahedral-complex-ntrt2026", driven_strings(morph)[:40])
    assert "received '44 strings'; expected 90 strings (or 40, the driven ones)" in str(err.value)
    assert "\n" not in str(err.value)


@pytest.mark.skipif(not OCTA.exists(), reason="NTRT's recordings are not on this machine")
def test_window_drives_the_recorded_strings():
    morph = load_morphology("octahedral-complex-ntrt2026")
    rec = read_recording(OCTA)
    (run,) = run_windows(morph, TrialConfig(engine="mujoco"), rec, [Window(50, (51, 52))])
    assert run.tension_n.shape == (2, 44) and np.all(np.isfinite(run.poses))
    # driven strings under NTRT's recorded rest lengths: their tensions near NTRT's (k = 10 000 N/m: a tension
    # error of 1 N is 0.01 cm of length); NTRT's tensions are in its force unit, the reader gives N
    assert np.max(np.abs(run.tension_n[0] - rec.tension_n[51])) < 1.0
