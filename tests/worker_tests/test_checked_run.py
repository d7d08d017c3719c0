"""Whole check intervals in one compiled call (worker.trial.loop.run_checked) give the bits, reasons, COM paths
and retries of the piecewise loop (stepper pieces, the engine's steps_ahead and Batch's checks in Python), on
every way the call stops early: a check near a guard's limit, a diverging law, a left-out contact that could form."""

from __future__ import annotations

import numpy as np
import pytest

from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.robot.morphology.variants import with_strings
from spinefarm.worker.trial import batch
from spinefarm.worker.trial.simulation import TrialConfig, random_unit_params, simulate

CASES = {  # name: (morphology, config, what the three trials must show)
    "sane": ("tetraspine-ntrt", TrialConfig(duration_s=0.5, settle_s=0.05, engine="mujoco"), "complete"),
    # the start's drop trips a 0.42 m/s speed guard in some gaits: the exact check decides
    "near a guard": ("tetraspine-ntrt", TrialConfig(duration_s=0.4, engine="mujoco", pose_jitter_cm=0.01,
                                                    max_body_speed_m_s=0.42), "reason"),
    # strings of 1e8 N/m: the speed guard trips at the first check; of 1e13 N/m: non-finite string state first
    "diverging body": ("stiff:1e8", TrialConfig(duration_s=0.3, engine="mujoco", refuse_unstable_dt=False), "reason"),
    "diverging law": ("stiff:1e13", TrialConfig(duration_s=0.3, engine="mujoco", refuse_unstable_dt=False), "law"),
    # the ribbed spine's ribs close a 1.3 mm gap at ~0.09 s: run again with segment contacts modelled
    "contact could form": ("ribbed", TrialConfig(duration_s=0.15, engine="mujoco"), "retry"),
}


def _runs(monkeypatch, morph, cfg, fused: bool) -> tuple[list, int]:
    calls = []
    plain = batch.Batch._run_checked

    def counted(self, n_steps, phase_start):
        calls.append(n_steps)
        return plain(self, n_steps, phase_start)
    monkeypatch.setattr(batch.Batch, "_run_checked", counted)
    if not fused:
        monkeypatch.setattr(batch, "checked_runner", lambda engine, law: None)
    outs = [simulate(morph, random_unit_params(morph, s), cfg, s) for s in (1, 2, 3)]
    monkeypatch.undo()
    return outs, len(calls)


@pytest.mark.parametrize("case", list(CASES))
def test_one_call_per_run_of_checks_gives_the_piecewise_bits(monkeypatch, case):
    name, cfg, shows = CASES[case]
    morph = with_strings(load_morphology("tetraspine-ntrt"), stiffness_n_per_m=float(name[6:])) \
        if name.startswith("stiff:") else load_morphology(name)
    fused, fused_calls = _runs(monkeypatch, morph, cfg, True)
    piecewise, piecewise_calls = _runs(monkeypatch, morph, cfg, False)
    assert fused_calls >= 3 and piecewise_calls == 0
    for a, b in zip(fused, piecewise, strict=True):
        ra, rb = a.result, b.result
        assert (ra.distance_m, ra.reason, ra.sim_time_s, ra.extras) == (rb.distance_m, rb.reason, rb.sim_time_s,
                                                                         rb.extras)
        assert np.array_equal(a.com_path_cm, b.com_path_cm)
    if shows == "law":
        assert all(o.result.reason.startswith("diverged: non-finite string state") for o in fused)
    elif shows == "reason":
        assert any(o.result.reason for o in fused)
    elif shows == "retry":
        assert all(o.result.extras.get("segment_contacts", "").startswith("modelled") for o in fused)
    else:
        # the start and 55 checks (0.05 s settle and 0.5 s, every 10 ms)
        assert not any(o.result.reason for o in fused) and all(len(o.com_path_cm) == 56 for o in fused)
