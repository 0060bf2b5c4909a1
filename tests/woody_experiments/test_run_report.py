"""The report's honesty: line accuracy beside scored accuracy, and the Φ threshold on the plot."""

from __future__ import annotations

import math

from woody_experiments.run_report import Spawn, Verdict, accuracy, accuracy_title, build_report, join, report_threshold


def rows_with_an_unscored_woody_fillet() -> list[dict]:
    spawns = [Spawn(sim_id=i, lane=i, mesh="m", k=k, mass=20.0, line_speed=0.508, stamp=0.0, spawn_x=-1.016)
              for i, k in enumerate((0.0, 100.0, 100.0))]
    verdicts = [Verdict(fillet_id=10 + i, lane=i, stamp=2.0, classification=c, grade="", phi=phi, hu_term=0.1,
                        solidity_term=0.01, nmdm=math.nan, mdm=math.nan, be=math.nan, threshold=11.02)
                for i, (c, phi) in enumerate((("normal", 18.0), ("woody", 8.0), ("unscored", math.nan)))]
    return join(spawns, verdicts)


def test_an_unscored_woody_fillet_lowers_the_line_accuracy_not_the_scored_one():
    acc = accuracy(rows_with_an_unscored_woody_fillet())
    assert (acc.scored, acc.correct, acc.unscored) == (2, 2, 1)
    assert acc.accuracy == 1.0 and math.isclose(acc.line_accuracy, 2 / 3)
    assert accuracy_title(acc) == "line accuracy 66.7%, scored 100.0%"


def test_the_report_states_both_accuracies_and_draws_the_graders_threshold(tmp_path):
    rows = rows_with_an_unscored_woody_fillet()
    assert report_threshold(rows, None) == 11.02
    assert report_threshold([], {"threshold": "9.5"}) == 9.5
    text = build_report(rows, tmp_path, notes=["skipped mesh x.stl: not a valid STL"]).read_text()
    assert "line accuracy (every fillet; one without a verdict is not diverted): **66.7%**" in text
    assert "accuracy: **100.0%**" in text and "- skipped mesh x.stl: not a valid STL" in text
