"""woody_vision.grading: Φ thresholds to normal / woody and grades, and their validation."""

from __future__ import annotations

import math

import pytest

from woody_vision.grading import GradingRules


def test_grading_rules_classify_lower_phi_as_woody():
    rules = GradingRules(threshold=10.0)
    assert rules.classify(5.4).label == "woody" and rules.classify(19.1).label == "normal"
    assert rules.classify(10.0).label == "normal"  # strictly below the threshold is woody
    assert rules.classify(5.4).grade is None
    graded = GradingRules(threshold=10.0, moderate_threshold=12.0, severe_threshold=6.0)
    assert [graded.grade(p) for p in (3.0, 6.0, 11.0, 12.0, 20.0)] == [
        "severe", "moderate", "moderate", "normal", "normal"]
    assert graded.classify(11.0).label == "normal" and graded.classify(11.0).grade == "moderate"
    assert GradingRules(threshold=10.0, severe_threshold=4.0).grade(8.0) == "moderate"
    for bad_phi in (math.nan, math.inf):
        with pytest.raises(ValueError):
            rules.classify(bad_phi)


@pytest.mark.parametrize("kwargs", [
    dict(threshold=0.0), dict(threshold=-1.0), dict(threshold=math.nan), dict(threshold=math.inf),
    dict(threshold=True), dict(threshold="10"), dict(threshold=10.0, moderate_threshold=8.0),
    dict(threshold=10.0, severe_threshold=10.0), dict(threshold=10.0, severe_threshold=12.0),
    dict(threshold=10.0, moderate_threshold=6.0, severe_threshold=8.0), dict(threshold=10.0, severe_threshold=-1.0),
])
def test_grading_rules_are_validated(kwargs):
    with pytest.raises(ValueError):
        GradingRules(**kwargs)
