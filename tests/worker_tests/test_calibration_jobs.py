"""A calibration's key leaves out `jobs` (the processes) because its result does not depend on them: the short
climb on MuJoCo proposes the same gaits a round whatever the processes, so one process and two find the same
distances on both tiers. Real trials; the climb's two trials are both among the bests and it beats every random
gait (its first trial does, so a climb whose rounds followed the processes draws its second one around another
centre, and the distances differ: checked by making the round `jobs` again)."""

from __future__ import annotations

import dataclasses

from spinefarm.worker.tools.calibrate import CalibrationSettings, calibrate

TINY = CalibrationSettings(gaits=3, search_trials=2, bests=2, duration_s=0.4, settle_s=0.1, jobs=1)


def test_one_process_and_two_calibrate_alike_under_one_key():
    alone = calibrate("tetraspine-ntrt", TINY)
    two = calibrate("tetraspine-ntrt", dataclasses.replace(TINY, jobs=2))
    mujoco = alone["distance_m"]["mujoco"]
    assert max(mujoco[3:]) > max(mujoco[:3])   # the climb moved its centre: where the next is drawn matters
    assert two["distance_m"] == alone["distance_m"] and len(mujoco) == 5
    assert two["decision"] == alone["decision"] and two["key"] == alone["key"] == TINY.key()
