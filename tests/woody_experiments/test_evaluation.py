"""Honest classification figures: Wilson intervals, one vote per run, leave-one-mesh-out, per-set report."""

from __future__ import annotations

import math

import pytest

from woody_experiments import evaluation
from woody_experiments.evaluation import Unit, leave_one_out, mesh_set, pooled, run_units, score
from woody_experiments.statistics import wilson_interval


def test_wilson_interval_matches_known_values():
    # Reference values (Wilson score interval, z = 1.96): 0/10 -> [0, 0.2775]; 5/10 -> [0.2366, 0.7634];
    # 18/18 -> [0.8241, 1]
    assert wilson_interval(0, 10) == pytest.approx((0.0, 0.27753), abs=1e-4)
    assert wilson_interval(5, 10) == pytest.approx((0.23659, 0.76341), abs=1e-4)
    assert wilson_interval(18, 18) == pytest.approx((0.82412, 1.0), abs=1e-4)
    lo, hi = wilson_interval(97, 100)
    assert lo < 0.97 < hi and hi - lo < 0.1
    assert all(math.isnan(v) for v in wilson_interval(0, 0))
    with pytest.raises(ValueError):
        wilson_interval(11, 10)


def test_lane_score_counts_every_scored_lane_of_one_mesh_and_speed():
    rows = [row("a", 0, 100, 0, 20.0), row("a", 0, 100, 1, 8.0), row("a", 100, 100, 0, 3.0),
            row("a", 100, 100, 1, math.nan, "unscored"), row("a", 100, 130, 0, 30.0), row("b", 0, 100, 0, 1.0)]
    assert evaluation.lane_score(rows, "a", 100.0, 10.0) == (2, 3)


def test_mesh_sets_by_name():
    assert mesh_set("generated-0003") == "generated"
    assert mesh_set("seed0002") == "reference" and mesh_set("scan_17") == "reference"


def row(mesh, k, speed, lane, phi, status="scored"):
    return {"mesh": mesh, "k": float(k), "speed_fpm": float(speed), "lane": lane, "mass": 20.0, "phi": phi,
            "status": status}


def test_lanes_of_a_run_give_one_vote_the_median():
    rows = [row("a", 0, 100, 0, 20.0), row("a", 0, 100, 1, 8.0), row("a", 0, 100, 2, 18.0),
            row("a", 100, 100, 0, 3.0), row("a", 100, 100, 1, math.nan, "unscored"), row("a", 100, 100, 2, 5.0),
            row("a", 40, 100, 0, 9.0)]  # neither normal nor severe: not a unit
    units = run_units(rows)
    assert units == [Unit("a", 0.0, 100.0, 18.0, 3), Unit("a", 100.0, 100.0, 4.0, 2)]
    # one lane misread (8.0 < 10) is outvoted by the other two
    assert score(units, 10.0).right == 2 and score(units, 10.0).total == 2 and score(units, 10.0).meshes == 1


def units_of(phis: dict[str, tuple[float, float]]) -> list[Unit]:
    return [Unit(m, k, 100.0, phi, 3) for m, (p0, p100) in phis.items() for k, phi in ((0.0, p0), (100.0, p100))]


def test_leave_one_out_chooses_each_threshold_without_the_held_out_mesh():
    units = units_of({"a": (20.0, 4.0), "b": (18.0, 6.0), "c": (9.0, 2.0)})
    folds = {f.held_out: f for f in leave_one_out(units)}
    assert set(folds) == {"a", "b", "c"}
    # without c the only perfect cut on a and b is midway between 6 and 18: it has not seen c's normal 9.0,
    # which it then calls woody; with c in training (folds a and b) the cut lies between 6 and 9
    assert folds["c"].threshold == pytest.approx(12.0) and folds["c"].train_balanced_accuracy == 1.0
    assert (folds["c"].test.right, folds["c"].test.total) == (1, 2)
    assert 6.0 < folds["a"].threshold < 9.0 and 6.0 < folds["b"].threshold < 9.0
    assert folds["a"].test.right == 2 and folds["b"].test.right == 2
    total = pooled(list(folds.values()))
    assert (total.right, total.total, total.meshes) == (5, 6, 3)


def test_leave_one_out_catches_a_mesh_the_others_cannot_predict():
    # c's stiff Φ sits above everything the other meshes call normal: no threshold from a and b can get it right
    folds = {f.held_out: f for f in leave_one_out(units_of({"a": (20.0, 4.0), "b": (18.0, 6.0), "c": (25.0, 19.0)}))}
    assert folds["c"].test.right == 1 and folds["c"].test.total == 2
    assert leave_one_out(units_of({"a": (20.0, 4.0)})) == []


def test_report_separates_sets_and_checks_the_targets():
    rows = []
    for mesh, p0, p100 in (("seed0000", 20.0, 4.0), ("seed0001", 18.0, 5.0), ("seed0002", 16.0, 6.0),
                           ("generated-0000", 22.0, 12.0)):
        rows += [row(mesh, 0, 100, lane, p0 + lane * 0.1) for lane in range(3)]
        rows += [row(mesh, 100, 100, lane, p100 + lane * 0.1) for lane in range(3)]
    lines, checks = evaluation.report(rows, threshold=10.0)
    text = "\n".join(lines)
    assert "| reference | 100 | 3 | 3 / 3 |" in text and "| generated | 100 | 1 | 1 / 1 |" in text
    assert "seed0002" in text and "Wilson" in text
    assert "| 100 | **all folds** | — | — | 100.0 % (6/6 runs, 3 meshes; 95 % CI 61.0–100.0 %) | 18/18 |" in text
    outcome = {name: ok for name, ok, _ in checks}
    assert outcome["reference meshes, 100 FPM: leave-one-out accuracy ≥ 97 %"] is True
    assert outcome["reference meshes, 100 FPM: Φ(k=0)/Φ(k=100) ≥ 3.0"] is True  # 18.1 / 5.1
