"""woody_experiments.line_grade: cuts fitted between classes, one vote per run, the line's figures."""

from __future__ import annotations

import math

import numpy as np
import pytest

from woody_common.line import REFERENCE_SPEED_MPS
from woody_experiments import line_grade
from woody_vision.grading import TIDY, FilletConditions


def row(k: float, line_phi: float, speed_mps: float = REFERENCE_SPEED_MPS, blunt: bool = False, mesh: str = "m",
        speed_fpm: float = 100.0, lane: int = 0, condition: str = "tidy") -> dict:
    return {"mesh": mesh, "k": k, "speed_fpm": speed_fpm, "condition": condition, "lane": lane, "status": "scored",
            "line_phi": line_phi, "speed_mps": speed_mps, "leading_end": "blunt" if blunt else "narrow"}


def synthetic_rows(rng: np.random.Generator) -> list[dict]:
    """Classes whose ln(score) falls with speed and for blunt-first fillets, as the line's do."""
    rows = []
    for k, level in ((0.0, math.log(16.0)), (10.0, math.log(8.0)), (20.0, math.log(6.0)), (40.0, math.log(3.5)),
                     (100.0, math.log(2.2))):
        for i in range(40):
            speed, blunt = rng.uniform(0.45, 0.72), bool(i % 2)
            score = level - 1.2 * (speed - REFERENCE_SPEED_MPS) - 0.2 * blunt + rng.normal(0.0, 0.05)
            rows.append(row(k, math.exp(score), speed, blunt, mesh=f"m{i}"))
    return rows


def test_true_grades_split_at_zero_and_forty():
    assert [line_grade.true_grade(k) for k in (0, 10, 20, 39.9, 40, 100, 400)] == [
        "normal", "moderate", "moderate", "moderate", "severe", "severe", "severe"]


def test_a_fitted_cut_follows_speed_and_leading_end_between_the_classes():
    rows = synthetic_rows(np.random.default_rng(3))
    rules = line_grade.fit_rules(rows)
    cut = rules.threshold
    assert cut.speed_slope == pytest.approx(-1.2, abs=0.1) and cut.blunt_offset == pytest.approx(-0.2, abs=0.05)
    assert 2.2 < cut.at(TIDY) < 16.0
    fast_blunt = FilletConditions(0.7, blunt_first=True)
    assert rules.is_woody(2.2 * math.exp(-1.2 * 0.19 - 0.2) * 1.3, fast_blunt)
    assert not rules.is_woody(16.0 * math.exp(-1.2 * 0.19 - 0.2) / 1.3, fast_blunt)
    runs = line_grade.graded_runs(rows, rules)
    summary = line_grade.summarise(runs)
    assert summary.right == summary.total == 80 and summary.severe_passed == 0 and summary.auc == 1.0
    # the grade refines the verdict: a moderate fillet the reject cut passes grades normal
    assert all((r.grade == "normal") == (r.label == "normal") for r in runs)
    assert summary.confusion[("normal", "normal")] == 40 and summary.confusion[("severe", "severe")] == 80
    moderate = [r for r in runs if line_grade.true_grade(r.k) == "moderate"]
    assert summary.confusion[("moderate", "moderate")] == sum(r.label == "woody" for r in moderate) > 0


def test_a_score_of_zero_is_left_out_of_its_class_line():
    rows = synthetic_rows(np.random.default_rng(3))
    with_zero = rows + [row(100.0, 0.0, mesh="flat")]  # a line read back to the axis: below every cut
    assert line_grade.fit_rules(with_zero).threshold == line_grade.fit_rules(rows).threshold


def test_a_cut_needs_rows_on_both_sides():
    with pytest.raises(ValueError, match="at least 4 scored rows"):
        line_grade.fit_cut([row(0, 16.0)] * 3, [row(100, 2.0)] * 10)


def test_a_run_votes_once_with_its_median_lane_and_unscored_lanes_are_left_out():
    rules = line_grade.fit_rules(synthetic_rows(np.random.default_rng(4)))
    lanes = [row(0.0, 15.0, lane=0), row(0.0, 1.0, lane=1), row(0.0, 14.0, lane=2),
             {**row(0.0, math.nan, lane=3), "status": "unscored"}]
    (run,) = line_grade.graded_runs(lanes, rules)
    assert run.score == 14.0 and run.label == "normal" and run.grade == "normal" and run.margin > 0
