"""A promoted parameter set goes on from the kept end of its last rung (worker.trial.continued) and ends in the bits
of a trial simulated from the start: distance, COT, work, the whole COM path. Real MuJoCo, the production trial.
The expectation is the from-the-start trial, run in a fresh set-up that never kept anything."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from spinefarm.robot.morphology.registry import load_morphology
from spinefarm.worker.trial.continued import RungEnd, RungEnds
from spinefarm.worker.trial.setup import SetupCache
from spinefarm.worker.trial.simulation import TrialConfig, TrialOutcome, random_unit_params, simulate

MORPH = load_morphology("tetraspine")
# the paper-size search's screen (docs/performance.md), short: a 0.6 s rung promoted to 1.5 s after a 0.3 s settle
SCREEN = TrialConfig(engine="mujoco", dt_s=0.002, settle_s=0.3, engine_options={"segment_contacts": "off"})
RUNG_S, FULL_S = 0.6, 1.5
SCORES = ("distance_m", "ntrt_distance_cm", "speed_cm_s", "work_j", "cot", "sim_time_s", "status", "reason")


def _run(params: np.ndarray, duration_s: float, cache: SetupCache, cfg: TrialConfig = SCREEN, seed: int = 7,
         resume: bool = True) -> TrialOutcome:
    return simulate(MORPH, params, dataclasses.replace(cfg, duration_s=duration_s), seed, controller="sidewinding",
                    setup=cache, resume=resume)


def _same_bits(a: TrialOutcome, b: TrialOutcome) -> None:
    for name in SCORES:
        assert getattr(a.result, name) == getattr(b.result, name), name
    assert a.com_path_cm.tobytes() == b.com_path_cm.tobytes()
    assert a.com_path_time_s.tobytes() == b.com_path_time_s.tobytes()


@pytest.mark.parametrize("cfg", [SCREEN, dataclasses.replace(SCREEN, engine_options={"segment_contacts": "auto"})],
                         ids=["contacts-off", "contact-guard"])
def test_a_promotion_continued_from_its_rung_gives_the_bits_of_one_simulated_from_the_start(cfg):
    sets = [random_unit_params(MORPH, s, "sidewinding") for s in (11, 12, 13)]
    kept = SetupCache()
    rungs = [_run(p, RUNG_S, kept, cfg) for p in sets]
    assert len({r.result.distance_m for r in rungs}) == 3   # distinct gaits: a mix-up would show
    continued = [_run(p, FULL_S, kept, cfg, seed=8 + i) for i, p in enumerate(sets)]  # promotions: their own seeds
    fresh = [_run(p, FULL_S, SetupCache(), cfg, seed=8 + i, resume=False) for i, p in enumerate(sets)]
    for r, c, f in zip(rungs, continued, fresh, strict=True):
        assert r.result.extras["continued_s"] == 0.0
        # settle and rung went on from the kept end: 0.3 + 0.6 s, to the step
        assert c.result.extras["continued_s"] == pytest.approx(cfg.settle_s + RUNG_S, abs=1e-12)
        assert "continued_s" not in f.result.extras
        assert c.result.seed == f.result.seed
        _same_bits(c, f)
        assert len(c.com_path_cm) > len(r.com_path_cm) and c.result.distance_m != r.result.distance_m


def test_a_rung_end_off_the_check_interval_continues_exactly():
    """A rung that ends between two checks (0.606 s, 303 steps of 2 ms: checks every 5 steps) goes on mid-interval."""
    p = random_unit_params(MORPH, 21, "sidewinding")
    kept = SetupCache()
    _run(p, 0.606, kept)
    c = _run(p, 1.0, kept)
    assert c.result.extras["continued_s"] == pytest.approx(0.906, abs=1e-12)
    _same_bits(c, _run(p, 1.0, SetupCache(), resume=False))


def test_a_set_up_without_the_end_simulates_from_the_start_with_the_same_bits():
    p = random_unit_params(MORPH, 31, "sidewinding")
    kept = SetupCache()
    _run(p, RUNG_S, kept)
    elsewhere = _run(p, FULL_S, SetupCache())  # another worker, or one restarted: nothing kept
    assert elsewhere.result.extras["continued_s"] == 0.0
    _same_bits(elsewhere, _run(p, FULL_S, kept))
    # another parameter set, another settle or check period, or a jittered start: none goes on from that end
    other = random_unit_params(MORPH, 32, "sidewinding")
    assert _run(other, FULL_S, kept).result.extras["continued_s"] == 0.0
    assert _run(p, FULL_S, kept, dataclasses.replace(SCREEN, settle_s=0.2)).result.extras["continued_s"] == 0.0
    assert _run(p, FULL_S, kept, dataclasses.replace(SCREEN, check_every_s=0.02)).result.extras["continued_s"] == 0.0


def test_a_shorter_trial_does_not_go_on_from_a_longer_ones_end():
    p = random_unit_params(MORPH, 41, "sidewinding")
    kept = SetupCache()
    _run(p, FULL_S, kept)
    short = _run(p, RUNG_S, kept)
    assert short.result.extras["continued_s"] == 0.0
    _same_bits(short, _run(p, RUNG_S, SetupCache(), resume=False))


def test_the_kept_ends_are_bounded_least_recently_used_first():
    ends = RungEnds(size=2)
    for i, key in enumerate("abc"):
        ends.put(key, RungEnd(None, (), None, 10 * (i + 1)))
    assert len(ends) == 2 and ends.get("a", 100) is None        # the oldest went
    assert ends.get("b", 100).done == 20                        # b used: now c is the oldest
    ends.put("d", RungEnd(None, (), None, 40))
    assert ends.get("c", 100) is None and ends.get("b", 100) is not None and ends.get("d", 100) is not None
    assert ends.get("d", 39) is None                            # a trial shorter than the end: from the start
    with pytest.raises(ValueError, match="received -1"):
        RungEnds(size=-1)


def test_an_evicted_end_means_a_re_simulation_with_the_same_bits():
    sets = [random_unit_params(MORPH, s, "sidewinding") for s in (51, 52, 53)]
    kept = SetupCache()
    for p in sets:
        _run(p, RUNG_S, kept)
    setup = next(iter(kept._items.values()))
    setup.rung_ends.size = 2
    setup.rung_ends.put("another", RungEnd(None, (), None, 1))  # trims to 2: the first two sets' ends go
    third = _run(sets[2], FULL_S, kept)
    first = _run(sets[0], FULL_S, kept)
    assert first.result.extras["continued_s"] == 0.0 and third.result.extras["continued_s"] > 0
    _same_bits(first, _run(sets[0], FULL_S, SetupCache(), resume=False))


def test_bullet_trials_always_run_from_the_start():
    """Bullet cannot restore a world exactly (engine ability "snapshot"): nothing is kept, nothing continued."""
    cfg = TrialConfig(engine="bullet", settle_s=0.0)
    p = random_unit_params(MORPH, 61, "sidewinding")
    kept = SetupCache()
    _run(p, 0.2, kept, cfg)
    again = _run(p, 0.4, kept, cfg)
    assert again.result.extras["continued_s"] == 0.0
    assert len(next(iter(kept._items.values())).rung_ends) == 0


def test_the_workers_evaluator_continues_a_promotion_it_ran_the_rung_of_and_no_other():
    """Two workers' evaluators (worker.service.assignment): the one that ran the rung goes on from its end, the other
    and an assignment sent from_start simulate from step 0; all three hold the same bits."""
    from spinefarm.protocol.work import TrialAssignment
    from spinefarm.worker.service.assignment import physics_evaluator

    unit = tuple(random_unit_params(MORPH, 71, "sidewinding").tolist())
    ran_rung, other = (physics_evaluator(MORPH, SCREEN, "sidewinding") for _ in range(2))
    ran_rung(TrialAssignment(0, 1, unit, 5, 60.0, RUNG_S))
    promotion = TrialAssignment(1, 2, unit, 6, 60.0, FULL_S)
    results = [ran_rung(promotion), other(promotion), ran_rung(dataclasses.replace(promotion, from_start=True))]
    assert [r.extras.get("continued_s") for r in results] == [pytest.approx(SCREEN.settle_s + RUNG_S, abs=1e-12),
                                                              0.0, None]
    for name in SCORES:
        assert len({getattr(r, name) for r in results}) == 1, name


def test_the_trial_limit_learns_its_rate_from_the_seconds_a_continued_trial_simulated():
    """A promotion to 11 s (1 s settle + 10 s) that went on from 6 s ran 5 s in 0.5 s: 0.1 s per simulated s, so a
    full 11 s trial of its kind gets 8 x 0.1 x 11 = 8.8 s, not 8 x 0.5 / 11 x 11 = 4 s."""
    from spinefarm.protocol.results import TrialResult
    from spinefarm.protocol.states import TrialStatus
    from spinefarm.worker.service.sandbox import TrialLimit, simulated_here_s

    continued = TrialResult(TrialStatus.COMPLETE, "", 0.1, 10.0, 1.0, 1.0, 1.0, 10.0, 0.5, 1.0, 0,
                            extras={"continued_s": 6.0})
    limit = TrialLimit(min_s=0.001, factor=8.0)
    limit.observe(continued.wall_time_s, simulated_here_s(11.0, continued), "promoted")
    assert limit.limit_s(11.0, "promoted") == pytest.approx(8.8)
    assert simulated_here_s(11.0, dataclasses.replace(continued, extras={})) == 11.0
