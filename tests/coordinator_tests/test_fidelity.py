"""Multi-fidelity search: successive halving over trial durations, end to end with real workers over
Zenoh, resumed after a SIGKILL mid-rung, and the promotion rule on a known set of results."""

from __future__ import annotations

import signal
import time

import numpy as np
import pytest

from spinefarm.coordinator.ladder.rungs import HalvingTrialScheduler, parse_rungs
from spinefarm.protocol.errors import ConfigError
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.states import TrialStatus
from spinefarm.storage.hdf5 import Hdf5Storage
from spinefarm.storage.hdf5_reader import read_run
from spinefarm.storage.memory import InMemoryStorage
from tests.coordinator_tests.helpers import free_endpoint, halving_ladder
from tests.coordinator_tests.procs import coordinator, stop, wait_status, worker


def _result(tid: int, distance: float) -> TrialResult:
    return TrialResult(TrialStatus.COMPLETE, "", distance, 0.0, distance, 1.0, 1.0, 1.0, 0.0, 1.0, 0,
                       trial_id=tid)


def _storage_with(objectives: list[float]) -> InMemoryStorage:
    from tests.storage_tests.conftest import make_meta

    st = InMemoryStorage()
    st.create_run(make_meta(n_params=3))
    for tid, obj in enumerate(objectives):
        st.add_trial(tid, np.full(3, 0.5), np.zeros(3), "monte_carlo", -1, 0, 0, 1.0)
        st.finish_trial(tid, _result(tid, obj), obj)
    return st


def test_the_best_third_of_a_rung_is_promoted_best_first_and_once():
    rungs = halving_ladder((1.0, 3.0), 3)
    st = _storage_with([0.1, 0.9, 0.5, 0.7, 0.2, 0.8])  # top third of 6: ids 1 and 5
    assert rungs.promotion(st) == 1
    st.add_trial(6, np.full(3, 0.5), np.zeros(3), "promoted", 1, 0, 1, 3.0)
    assert rungs.promotion(st) == 5
    st.add_trial(7, np.full(3, 0.5), np.zeros(3), "promoted", 5, 0, 1, 3.0)
    assert rungs.promotion(st) is None  # both promoted; the top rung is never promoted further
    st.finish_trial(6, _result(6, 0.3), 0.3)
    assert st.best_ids(2) == [6, 1]  # a full-length trial ranks before any screened one


@pytest.mark.parametrize(("text", "eta"), [("30,10", 3), ("10,10", 3), ("0,10", 3), ("ten", 3), ("10,30", 1)])
def test_bad_rungs_are_refused_with_what_was_expected(text, eta):
    with pytest.raises(ConfigError):
        halving_ladder(parse_rungs(text), eta)


def _check_fidelity(out, budget: int, rungs: HalvingTrialScheduler) -> None:
    with Hdf5Storage.open_read(out) as s:
        c = s.columns()
        assert set(c["status"].tolist()) == {b"complete"}
        rung = c["rung"]
        assert int((rung == 0).sum()) == budget  # the budget counts parameter sets
        promoted = c["phase"] == b"promoted"
        parents = c["parent"][promoted]
        assert len(set(parents.tolist())) == len(parents)  # each row promoted at most once
        np.testing.assert_array_equal(rung[promoted], rung[parents] + 1)
        np.testing.assert_array_equal(c["params_unit"][promoted], c["params_unit"][parents])
        np.testing.assert_array_equal(c["duration_s"], np.asarray(rungs.settings.durations_s())[rung])
        for r in range(rungs.top):  # about 1/eta of each rung goes on (a few more if bests came late)
            n_r, n_next = int((rung == r).sum()), int((rung == r + 1).sum())
            assert n_r // rungs.eta <= n_next <= n_r // rungs.eta + 1 + n_r // (2 * rungs.eta)
        best_screened = int(np.flatnonzero(rung == 0)[np.argmax(c["objective"][rung == 0])])
        assert best_screened in set(parents.tolist())  # the best screened parameter set always goes on
        assert s.best(1)[0].rung == rungs.top


def test_a_multi_fidelity_search_stores_every_evaluation_once_with_its_fidelity(tmp_path):
    ep, out = free_endpoint(), tmp_path / "run.h5"
    rungs = halving_ladder((0.01, 0.02, 0.04), 3)
    coord = coordinator(ep, out, "sphere:3", "--trials", "27", "--rungs", "0.01,0.02,0.04", "--eta", "3",
                        "--run-id", "mf")
    workers = [worker(ep, "mf", f"w{i}", batch=2) for i in range(2)]
    try:
        assert coord.wait(90) == 0
        _check_fidelity(out, 27, rungs)
    finally:
        stop(coord, *workers)
    # the API counts evaluations against the evaluations planned, parameter sets against the budget
    from spinefarm.api.app import create_app
    from tests.http_server import served

    with served(create_app(runs_dir=tmp_path)) as client:
        st = client.get("/runs/mf").json()
    rows = len(read_run(out)[1]["trial_id"])
    assert (st["trials_budget"], st["parameter_sets_sampled"], st["trials_planned"]) == (27, 27, 27 + 9 + 3)
    assert st["trials_done"] == rows and rows >= 27 + 9 + 3


def test_a_multi_fidelity_search_killed_mid_rung_resumes_to_its_exact_budget(tmp_path):
    ep, out = free_endpoint(), tmp_path / "run.h5"
    rungs = halving_ladder((0.05, 0.1), 3)
    coord = coordinator(ep, out, "sphere:3", "--trials", "60", "--rungs", "0.05,0.1", "--eta", "3", "--run-id", "mfk")
    workers = [worker(ep, "mfk", f"w{i}", batch=1) for i in range(2)]
    resumed = None
    try:
        wait_status(out, lambda st: st["trials_complete"] >= 20, "20 evaluations flushed", timeout_s=90)
        coord.send_signal(signal.SIGKILL)
        coord.wait(10)
        _, before = read_run(out)
        assert (before["rung"] == 1).any() and (before["rung"] == 0).sum() < 60  # killed mid-search
        time.sleep(0.2)
        resumed = coordinator(ep, out, "--resume", str(out))
        assert resumed.wait(120) == 0
        _check_fidelity(out, 60, rungs)
    finally:
        stop(coord, *workers, *([resumed] if resumed else []))


def test_a_mujoco_screen_with_a_bullet_judge_reports_the_judges_distance(tmp_path, capsys):
    """Physics end to end: MuJoCo screens two rungs, the best full-length trial is re-simulated in
    Bullet at 0.25 ms, and that distance is what the run reports."""
    import subprocess
    import sys

    from tests.coordinator_tests.procs import ROOT

    out = tmp_path / "run.h5"
    r = subprocess.run([sys.executable, "-m", "spinefarm", "search", "tetraspine-ntrt", "--engine", "mujoco",
                        "--rungs", "0.3,0.9", "--eta", "2", "--trials", "4", "--workers", "2", "--settle", "0.2",
                        "--out", str(out), "--api-port", "-1"], cwd=ROOT, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    with Hdf5Storage.open_read(out) as s:
        best = s.best(1)[0]
        assert best.rung == 1 and best.duration_s == 0.9 and best.engine == "mujoco"
        assert best.verification == "judged"  # another engine: its distance counts, the ratio is stored
        assert best.judge_ratio == pytest.approx(best.distance_m / best.verify_distance_m)
        assert np.isfinite(best.verify_distance_m) and best.verify_distance_m != best.distance_m
        assert s.run_meta().settings.judge.rung.engine == "bullet"
        # both engines are installed: the judged best's second opinion is MuJoCo at 1 ms, a row of its own, and
        # that is where the screen ran this very row, so the opinion is its bits again, whatever the judge said
        ev = s.evaluations()
        opinion = ev["kind"] == b"opinion"
        assert ev["trial_id"][opinion].tolist() == [best.trial_id]
        assert (ev["engine"][opinion][0], ev["dt_s"][opinion][0]) == (b"mujoco", 0.001)
        assert ev["distance_m"][opinion][0] == best.distance_m
        c = s.columns()  # a screened best is provisional: only full-length trials go to the judge
        assert set(c["verification"][c["rung"] == 0].tolist()) == {b""}
        from spinefarm.api.views import trial_view

        view = trial_view(s, best)["verification"]
        assert view["judge"] == "bullet at 0.25 ms" and view["label"] == "judged in bullet"
        assert view["screen_distance_m"] == best.distance_m and view["judge_distance_m"] == best.verify_distance_m
    assert f"judged in bullet: {best.verify_distance_m:.4g} m" in r.stdout and "screen/judge ratio" in r.stdout
    # `trial --run` re-runs the stored best: in its own engine it is the stored result, and in Bullet at the
    # judge's step it is the judge's distance
    import json

    from spinefarm.cli.main import main

    def rerun(*flags: str) -> dict:
        assert main(["trial", "--run", str(out), "--json", *flags]) == 0
        return json.loads(capsys.readouterr().out)

    again = rerun()
    assert again["distance_m"] == best.distance_m and again["extras"]["engine"] == "mujoco"
    assert again["rerun_of"] == {"run": str(out), "trial_id": best.trial_id}
    assert rerun("--engine", "bullet", "--dt", "0.00025")["distance_m"] == best.verify_distance_m
    first = rerun("--trial-id", "0")
    with Hdf5Storage.open_read(out) as s:
        assert first["distance_m"] == s.trial(0).distance_m and s.trial(0).duration_s == 0.3
    assert main(["trial", "--run", str(out), "--trial-id", "999"]) == 2
    assert "no such trial" in capsys.readouterr().err


def test_at_the_end_the_best_goes_on_through_rungs_holding_fewer_rows_than_eta():
    """Six sets on three rungs at eta 4: the first rung's quota is one set (6 // 4), the second rung then holds
    one row, of which 1 // 4 = 0 would go on; once sampling is done, its best still reaches the full length."""
    rungs = halving_ladder((0.5, 1.0, 3.0), 4)
    st = _storage_with([0.1, 0.9, 0.5, 0.7, 0.2, 0.8])
    assert rungs.promotion(st) == 1  # the quota of the first rung: its best
    st.add_trial(6, np.full(3, 0.5), np.zeros(3), "promoted", 1, 0, 1, 1.0)
    st.finish_trial(6, _result(6, 0.95), 0.95)
    assert rungs.promotion(st) is None  # while sampling goes on, one row of rung 1 promotes nothing
    assert rungs.promotion(st, sampling_done=True) == 6  # at the end the best goes on to the full length
    st.add_trial(7, np.full(3, 0.5), np.zeros(3), "promoted", 6, 0, 2, 3.0)
    assert rungs.promotion(st, sampling_done=True) is None  # and once: nothing more to promote


def test_a_search_that_keeps_improving_promotes_about_a_third_and_always_its_best():
    """Hill climbing makes each new trial better than the last: every one enters the top third when it
    finishes, but only a third (plus late bests) may go on."""
    rungs = halving_ladder((1.0, 3.0), 3)
    st = _storage_with([])
    n_promoted = 0
    for i in range(30):
        tid = st.n_trials()
        st.add_trial(tid, np.full(3, 0.5), np.zeros(3), "gaussian", -1, 0, 0, 1.0)
        st.finish_trial(tid, _result(tid, float(i)), float(i))
        while (source := rungs.promotion(st, sampling_done=i == 29)) is not None:
            st.add_trial(st.n_trials(), np.full(3, 0.5), np.zeros(3), "promoted", source, 0, 1, 3.0)
            n_promoted += 1
    assert 10 <= n_promoted <= 12 + 3  # a third of 30, and the late bests
    best = int(np.argmax(np.where(st.columns()["rung"] == 0, st.columns()["objective"], -np.inf)))
    assert best in set(st.columns()["parent"][st.columns()["phase"] == b"promoted"].tolist())


def _study(sampler_name: str, rungs: HalvingTrialScheduler | None, budget: int = 12):
    from spinefarm.coordinator.samplers import make_sampler
    from spinefarm.coordinator.study import Study
    from spinefarm.protocol.params import ParamSpace, ParamSpec
    from tests.storage_tests.conftest import make_meta

    st = InMemoryStorage()
    st.create_run(make_meta(n_params=3))
    space = ParamSpace("test", tuple(ParamSpec(f"p{i}", 0.0, 1.0) for i in range(3)))
    sampler = make_sampler(sampler_name, 3, 7, budget=budget, objective="distance", startup_trials=4)
    return Study(st, sampler, space, budget, lambda r: r.distance_m, seed=7, trial_scheduler=rungs), st


def _drive(study, st) -> None:
    """Answer every ask at once with a score that depends on the parameters and the rung's duration."""
    while (tid := study.ask()) is not None:
        row = st.trial(tid)
        score = float(np.sum(row.params_unit)) * (1 + row.rung)  # a longer rung scores higher
        study.tell(_result(tid, score))


@pytest.mark.parametrize("sampler", ["random", "paper", "cmaes", "tpe"])
def test_samplers_see_the_first_rung_only_so_rungs_do_not_change_their_proposals(sampler):
    plain, plain_st = _study(sampler, None)
    _drive(plain, plain_st)
    screened, screened_st = _study(sampler, halving_ladder((1.0, 3.0), 3))
    _drive(screened, screened_st)
    c = screened_st.columns()
    assert int((c["phase"] == b"promoted").sum()) >= 4  # promotions were interleaved with sampling
    first = c["params_unit"][c["rung"] == 0]
    # the k-th parameter set is the same with and without rungs: promoted rows neither shift the
    # sampler's stream nor teach it their (longer, incomparable) scores. The hill climber's centre is
    # the best full-length gait, so only its Monte Carlo phase (4 trials here) must match.
    n = 4 if sampler == "paper" else len(first)
    np.testing.assert_array_equal(first[:n], plain_st.columns()["params_unit"][:n])
    parents = c["parent"][c["phase"] == b"gaussian"]
    assert all(c["rung"][p] == 0 for p in parents)  # a hill-climbing centre is a first-rung row id
