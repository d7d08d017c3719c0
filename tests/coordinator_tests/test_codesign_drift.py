"""A co-designed run is watched as any other: its judge's drifting ratios raise the screen's fidelity exactly as
in a run of the fixed body, and the run says what its calibration covers (the base body) and what the judge's
ratios on sampled bodies show, in the report, the status and /runs/ID/meta (docs/codesign.md)."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from spinefarm.api.app import create_app
from spinefarm.cli.report import final_report
from spinefarm.coordinator.problem import build_run_config
from spinefarm.coordinator.setup import SearchSettings, new_run
from spinefarm.protocol.envelope import decode_message
from spinefarm.protocol.envelope import encode_message as enc
from spinefarm.protocol.results import TrialResult
from spinefarm.protocol.settings import JudgePolicy, Rung
from spinefarm.protocol.states import TrialStatus
from spinefarm.protocol.submissions import ResultSubmission, SubmittedResult
from spinefarm.protocol.work import WorkGrant, WorkRequest
from tests.coordinator_tests.helpers import FakeClock
from tests.http_server import served

SPEC = textwrap.dedent("""\
    base: tetraspine-ntrt
    name: co-spine
    search:
      segments.rod_length_scale: [0.7, 1.3]
      rod_materials.rod.density_kg_per_cm3: [0.0098, 0.0182]
    """)


RATIOS = (1.5, 2.0, 3.0)  # screen / judge of the first three judged bests: median 2 (mean 2.17), outside [0.8, 1.2]


def _answer(core, n: int, judged: int) -> WorkGrant:
    """Take up to n tasks; every trial a new best (trial_id + 1 m) on its own body, the judge measuring
    1 / RATIOS[judged] of it."""
    grant = decode_message(core.handle_work(enc(WorkRequest("w1", n))), WorkGrant)
    items = []
    for a in grant.assignments:
        judge = a.fidelity.task == "judge"
        distance = (a.trial_id + 1) / RATIOS[judged] if judge else float(a.trial_id + 1)
        r = TrialResult(TrialStatus.COMPLETE, "", distance, 0.0, 1.0, 1.0, 1.0, 1.0, 0.0, 1.0, a.seed,
                        trial_id=a.trial_id, extras={"body_hash": f"{a.trial_id + 1:016x}"})
        items.append(SubmittedResult(a.lease_id, r))
    if items:
        core.handle_results(enc(ResultSubmission("w1", tuple(items))))
    return grant


def _drifting_run(tmp_path: Path, source: str):
    """A 20-trial run screened in MuJoCo and judged in Bullet at 0.25 ms (drift 0.2) until the judge has run
    three bests: (the status's fidelity_raised, the next trial's engine and step, the run file)."""
    config = build_run_config("drift", source, trial_overrides={"engine": "mujoco"})
    out = tmp_path / "drift.h5"
    core, storage = new_run(config, SearchSettings(trials=20, judge=JudgePolicy(rung=Rung("bullet", 2.5e-4),
                                                                              drift=0.2)), out, FakeClock())
    try:
        judged = 0
        for _ in range(40):
            judged += sum(a.fidelity.task == "judge" for a in _answer(core, 1, judged).assignments)
            if judged == 3:
                break
        raised = core.status()["fidelity_raised"]
        grant = decode_message(core.handle_work(enc(WorkRequest("w1", 2))), WorkGrant)
        trial = [(a.fidelity.engine, a.fidelity.dt_s) for a in grant.assignments if a.fidelity.task == "trial"]
        report = final_report(storage, out, verdict="", done=False)
    finally:
        storage.close()
    return raised, trial[0], report, out


@pytest.fixture(scope="module")
def both(tmp_path_factory):
    folder = tmp_path_factory.mktemp("codesign-drift")
    (folder / "co.yaml").write_text(SPEC)
    (folder / "fixed").mkdir()
    (folder / "codesign").mkdir()
    return {"fixed": _drifting_run(folder / "fixed", "tetraspine-ntrt"),
            "codesign": _drifting_run(folder / "codesign", str(folder / "co.yaml"))}


def test_the_drift_rule_fires_in_a_codesigned_run_as_in_a_fixed_body_one(both):
    fixed, codesign = both["fixed"], both["codesign"]
    # the judge measures 1/1.5, 1/2, 1/3 of the screen's distance: median ratio 2, outside [0.8, 1.2]
    assert fixed[0] is not None and "ratio 2" in fixed[0]
    assert codesign[0] == fixed[0]
    # from then on new trials leave the MuJoCo screen for Bullet at 4x the judge's step, in both
    assert codesign[1] == fixed[1] == ("bullet", pytest.approx(1e-3))


def test_the_run_says_what_its_calibration_covers_and_what_the_judge_saw(both):
    fixed_report, report = both["fixed"][2], both["codesign"][2]
    assert "co-designed" not in fixed_report
    line = next(x for x in report.splitlines() if x.startswith("co-designed"))
    # no --engine auto here: no calibration chose the screen; three judged bests on three sampled bodies
    assert "the calibration covers none: the engine was given (mujoco)" in line
    assert "3 judged, median screen-to-judge ratio 2 (1.5-3)" in line and "band [0.8, 1.2]" in line
    out = both["codesign"][3]
    with served(create_app(runs_dir=out.parent)) as client:
        meta = client.get("/runs/drift/meta").json()["codesign"]
        status = client.get("/runs/drift").json()["codesign"]
    assert meta == status and meta["statement"] == line
    assert meta["judge_ratios_on_sampled_bodies"] == {"judged": 3, "median": 2.0, "min": 1.5, "max": 3.0}
    assert meta["sampled_bodies"] >= 3 and len(meta["base_body_hash"]) == 16
    with served(create_app(runs_dir=both["fixed"][3].parent)) as client:
        assert client.get("/runs/drift/meta").json()["codesign"] is None
        assert client.get("/runs/drift").json()["codesign"] is None
