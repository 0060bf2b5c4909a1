"""woody_vision.grading: Φ thresholds to normal / woody and grades, and their validation."""

from __future__ import annotations

import math

import pytest

from woody_common.line import REFERENCE_SPEED_MPS
from woody_vision.grading import (
    TIDY,
    Cut,
    FilletConditions,
    FittedRange,
    GradingRules,
    fitted_range_of,
    is_woody_array,
)


def test_grading_rules_classify_lower_phi_as_woody():
    rules = GradingRules(threshold=10.0)
    assert rules.classify(5.4).label == "woody" and rules.classify(19.1).label == "normal"
    assert rules.classify(10.0).label == "normal"  # strictly below the threshold is woody
    assert rules.classify(5.4).grade is None
    graded = GradingRules(threshold=10.0, severe_threshold=6.0)
    assert [graded.grade(p) for p in (3.0, 6.0, 9.9, 10.0, 20.0)] == [
        "severe", "moderate", "moderate", "normal", "normal"]
    for phi in (3.0, 6.0, 9.9, 10.0, 20.0):  # the grade refines the verdict: normal exactly when it passes
        decision = graded.classify(phi)
        assert (decision.grade == "normal") == (decision.label == "normal")
    for bad_phi in (math.nan, math.inf):
        with pytest.raises(ValueError):
            rules.classify(bad_phi)


@pytest.mark.parametrize("kwargs", [
    dict(threshold=0.0), dict(threshold=-1.0), dict(threshold=math.nan), dict(threshold=math.inf),
    dict(threshold=True), dict(threshold="10"),
    dict(threshold=10.0, severe_threshold=10.0), dict(threshold=10.0, severe_threshold=12.0),
    dict(threshold=10.0, severe_threshold=-1.0),
])
def test_grading_rules_are_validated(kwargs):
    with pytest.raises(ValueError):
        GradingRules(**kwargs)


def test_a_cut_follows_the_measured_speed_and_leading_end():
    cut = Cut(8.0, speed_slope=-1.5, blunt_offset=-0.2)
    assert cut.at(TIDY) == pytest.approx(8.0)
    assert cut.at(FilletConditions(REFERENCE_SPEED_MPS + 0.2)) == pytest.approx(8.0 * math.exp(-0.3))
    assert cut.at(FilletConditions(blunt_first=True)) == pytest.approx(8.0 * math.exp(-0.2))
    assert cut.at(FilletConditions(math.nan)) == pytest.approx(8.0)  # speed unknown: the base
    assert Cut.of(5.0) == Cut(5.0) and Cut.of([5.0, 1.0, 0.5, 0.1, 2.0]).as_list() == [5.0, 1.0, 0.5, 0.1, 2.0]
    rules = GradingRules(cut)
    fast = FilletConditions(REFERENCE_SPEED_MPS + 0.2)
    assert rules.is_woody(7.0) and not rules.is_woody(7.0, fast)  # the cut falls with speed: 7 is normal there
    assert rules.classify(7.0, fast).threshold == pytest.approx(cut.at(fast))


@pytest.mark.parametrize("value", [[1.0, 2.0], [0.0, 0.0, 0.0], [5.0, math.nan, 0.0], "5"])
def test_malformed_cuts_are_refused(value):
    with pytest.raises(ValueError):
        Cut.of(value)


def test_the_grade_cuts_must_stay_ordered_for_either_leading_end():
    with pytest.raises(ValueError, match="severe_threshold"):
        GradingRules(Cut(8.0), Cut(6.0, blunt_offset=1.0))  # blunt first: severe 16 > reject 8


def test_a_cut_allows_for_a_turned_or_longer_fillet():
    cut = Cut(8.0, turn_slope=-0.01, length_slope=2.0)
    assert cut.at(FilletConditions(turn_deg=20.0)) == pytest.approx(8.0 * math.exp(-0.2))
    assert cut.at(FilletConditions(length_m=0.24)) == pytest.approx(8.0 * math.exp(0.1))
    assert cut.at(FilletConditions(turn_deg=math.nan, length_m=math.nan)) == pytest.approx(8.0)


def test_one_rule_strictly_below_for_a_fillet_and_for_arrays():
    rules = GradingRules(10.0)
    scores = [9.99, 10.0, 10.01]
    assert list(is_woody_array(scores, 10.0)) == [rules.is_woody(s) for s in scores] == [True, False, False]
    assert is_woody_array([[1.0], [3.0]], [2.0, 4.0]).tolist() == [[True, True], [False, True]]  # broadcasts


RANGE = FittedRange(0.45, 0.72, 35.0, 0.15, 0.25)


@pytest.mark.parametrize(("conditions", "says"), [
    (FilletConditions(2.03, False, 10.0, 0.2), "measured speed 2.03 m/s, the cuts were fitted on 0.45-0.72 m/s"),
    (FilletConditions(0.30, False, 10.0, 0.2), "measured speed 0.30 m/s"),
    (FilletConditions(0.6, False, 44.0, 0.2), "measured turn 44 deg, the cuts were fitted on 0-35 deg"),
    (FilletConditions(0.6, False, 10.0, 0.29), "measured body length 0.290 m"),
    (FilletConditions(0.6, False, 10.0, 0.12), "measured body length 0.120 m"),
])
def test_conditions_outside_the_fitted_range_say_which_and_where(conditions, says):
    assert RANGE.outside(conditions).startswith("outside the calibration: ") and says in RANGE.outside(conditions)


def test_inside_within_the_measurement_slack_or_unmeasured_is_inside():
    assert RANGE.outside(FilletConditions(0.74, True, 36.5, 0.28)) == ""
    assert RANGE.outside(FilletConditions(0.43, True, 0.0, 0.13)) == ""
    assert RANGE.outside(FilletConditions(math.nan, False, math.nan, math.nan)) == ""


def test_a_fitted_range_is_validated_and_spans_its_rows():
    with pytest.raises(ValueError, match="minimum exceeds its maximum"):
        FittedRange(0.8, 0.4, 10.0, 0.1, 0.2)
    with pytest.raises(ValueError, match="a fitted range is"):
        FittedRange.of([0.4, 0.8])
    rows = [FilletConditions(0.5, False, 3.0, 0.2), FilletConditions(0.7, True, 30.0, 0.16),
            FilletConditions(math.nan, False, math.nan, math.nan)]
    assert fitted_range_of(rows) == FittedRange(0.5, 0.7, 30.0, 0.16, 0.2)
    assert FittedRange.of(RANGE.as_list()) == RANGE
