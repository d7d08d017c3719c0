"""Every sampled body is checked before it runs: real bodies (the 3-segment Tetraspine with one constant
changed) that cannot be searched are told apart, each with its reason, and nothing raises."""

from __future__ import annotations

import pytest

from spinefarm.protocol.states import TrialStatus
from spinefarm.robot.morphology.specfile import SPEC_DIR, from_document, parse_spec, spec_document
from spinefarm.robot.morphology.specsearch import with_body
from spinefarm.worker.trial.feasibility import FeasibilityCache, check_body, infeasible_result

PATH = SPEC_DIR / "tetraspine-ntrt.yaml"


def body(**values: float):
    spec, doc = spec_document(PATH.read_text(), str(PATH))
    return from_document(spec, with_body(doc, {k.replace("__", "."): v for k, v in values.items()}))


def test_the_file_as_written_is_feasible():
    verdict = check_body(body())
    assert verdict.ok and verdict.reason == ""


@pytest.mark.parametrize(("values", "reason"), [
    # segments 0.3 cm apart: a rod of one passes within the two 0.5 cm radii of the next one's
    ({"segments__spacing_scale": 0.01}, "rods through each other"),
    # 400 N on 1000 N/m is 40 cm of stretch: more than the 28.6 cm outer strings are long
    ({"string_materials__outer__pretension_n": 400.0}, "strings cannot hold their pretension"),
    # rods 357 times as dense (5 kg/cm^3): segments of ~880 kg drop onto the ground and the run diverges
    ({"rod_materials__rod__density_kg_per_cm3": 5.0}, "no stable step: diverged"),
    # segments three times as far apart: the control lengths (15-17 cm) pull them together for seconds
    ({"segments__spacing_scale": 3.0}, "no rest shape"),
])
def test_bodies_that_cannot_be_searched(values, reason):
    verdict = check_body(body(**values))
    assert not verdict.ok and verdict.reason.startswith(reason), verdict.reason
    result = infeasible_result(verdict, seed=4, trial_id=9)
    # the failed trial's reason is the documented prefix and the verdict's reason (docs/codesign.md)
    assert result.status == TrialStatus.FAILED and result.reason == "infeasible: " + verdict.reason
    assert result.trial_id == 9


def test_strings_that_hold_nothing():
    # zero gains and no offset: the impedance law's target tension max(0, 0 + 0 (L - Lc) + 0 v) is 0 N, so
    # no string of any joint pulls and the segments lie side by side on the ground
    text = ("base: tetraspine-ntrt\nname: limp\ncontrol:\n  impedance:\n"
            "    outer: {position_gain_n_per_m: 0, velocity_gain_n_s_per_m: 0}\n"
            "    inner: {position_gain_n_per_m: 0, velocity_gain_n_s_per_m: 0}\n")
    verdict = check_body(parse_spec(text, str(PATH.parent / "limp-test.yaml")))
    assert not verdict.ok and verdict.reason.startswith("strings slack: no string of joint 0"), verdict.reason


def test_verdicts_are_kept_per_body_hash():
    cache = FeasibilityCache(size=2)
    good, crossed = body(), body(segments__spacing_scale=0.01)
    assert cache.check(good).ok and cache.check(body()).ok  # the same body built again: the same hash
    assert cache.checked == 1
    assert not cache.check(crossed).ok and cache.checked == 2
    assert not cache.check(crossed).ok and cache.checked == 2
    far = body(segments__spacing_scale=3.0)
    assert not cache.check(far).ok and cache.checked == 3  # size 2: the least recently used, `good`, goes
    assert not cache.check(crossed).ok and cache.checked == 3
    assert cache.check(good).ok and cache.checked == 4
