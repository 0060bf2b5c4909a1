"""The report's honesty: line accuracy beside scored accuracy, the Φ threshold on the plot, woody fillets diverted
or missed per condition, and the three-class grade."""

from __future__ import annotations

import math

from woody_common.calibration import resolved_calibration
from woody_experiments.run_report import (
    CALIBRATED_SPEEDS,
    GATE_MISSED_REASON,
    UNSCORED_DIVERTED,
    Spawn,
    Verdict,
    accuracy,
    accuracy_title,
    build_report,
    calibrated_speeds,
    diversion_summary,
    gate_missed,
    gate_timing_line,
    grade_confusion,
    join,
    other_camera_note,
    read_csv,
    uncalibrated_speed_note,
    verdict_table,
    write_csv,
)


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


def test_the_report_states_both_accuracies_and_draws_each_fillets_cut(tmp_path):
    rows = rows_with_an_unscored_woody_fillet()
    text = build_report(rows, tmp_path, notes=["skipped mesh x.stl: not a valid STL"]).read_text()
    assert "line accuracy (every fillet; one without a verdict is not diverted): **66.7%**" in text
    assert "accuracy: **100.0%**" in text and "- skipped mesh x.stl: not a valid STL" in text
    assert "## Terms and the recording" in text and "verdicts.md)" in text and "file://" not in text


def rows_of_a_messy_line() -> list[dict]:
    """k 0, 20 and 100 twice; the line's verdict fields; a merged window leaves one woody fillet unscored."""
    ks = (0.0, 20.0, 100.0, 100.0, 0.0)
    spawns = [Spawn(sim_id=i, lane=i % 3, mesh="m", k=k, mass=20.0, line_speed=0.508, stamp=i * 0.5,
                    spawn_x=-1.016) for i, k in enumerate(ks)]
    decided = [("normal", "normal", 14.0, "narrow"), ("woody", "moderate", 8.0, "blunt"),
               ("woody", "severe", 3.0, "narrow"), ("unscored", "", math.nan, "blunt"),
               ("woody", "moderate", 6.5, "blunt")]
    verdicts = [Verdict(fillet_id=20 + i, lane=i % 3, stamp=i * 0.5 + 2.0, classification=c, grade=g, phi=12.0,
                        hu_term=0.1, solidity_term=0.01, nmdm=math.nan, mdm=math.nan, be=math.nan, threshold=7.2,
                        reason="merged with a neighbour at the measuring point" if c == "unscored" else "",
                        score=score, line_phi=score, line_fraction=0.5, speed=0.51, leading_end=end,
                        rejected_frames=2 if c == "unscored" else 0)
                for i, (c, g, score, end) in enumerate(decided)]
    return join(spawns, verdicts)


def test_an_unscored_woody_fillet_is_diverted_when_the_gate_diverts_unscored_ones():
    rows = rows_of_a_messy_line()
    kept, diverted = accuracy(rows), accuracy(rows, divert_unscored=True)
    assert (kept.woody, kept.woody_diverted, diverted.woody_diverted) == (2, 1, 2)
    assert (diverted.correct, diverted.total) == (2, 5)  # k 20 is normal to the reject decision (woody k >= 50)
    assert math.isclose(kept.line_accuracy, 2 / 5) and math.isclose(diverted.line_accuracy, 3 / 5)
    assert rows[3]["true_grade"] == "severe" and rows[1]["true_grade"] == "moderate"
    assert grade_confusion(rows) == {("normal", "normal"): 1, ("moderate", "moderate"): 1,
                                     ("severe", "severe"): 1, ("severe", "unscored"): 1,
                                     ("normal", "moderate"): 1}


def test_the_report_and_csv_carry_the_line_fields_grades_and_diversions(tmp_path):
    rows = rows_of_a_messy_line()
    text = build_report(rows, tmp_path, run_info={UNSCORED_DIVERTED: True}).read_text()
    assert "- diverted 2 of 2 woody fillets (diverted: graded woody, or unscored (reject_gate diverts" in text
    assert "- correct verdicts (normal/woody as the truth): 2 of 5 fillets" in text
    assert "| 100 FPM, blunt first | 1 | 1 | – |" in text and "| 100 FPM, narrow first | 1 | 1 | – |" in text
    assert "| truth \\ graded | normal | moderate | severe | unscored |" in text
    assert "| normal | 1 | 1 | 0 | 0 |" in text and "| severe | 0 | 0 | 1 | 1 |" in text
    assert "23: merged with a neighbour at the measuring point" in text
    kept = build_report(rows, tmp_path / "kept").read_text()  # a run that does not say: unscored ones pass
    assert "| 100 FPM, blunt first | 1 | 0 | 23 (unscored, -) |" in kept
    back = read_csv(write_csv(rows, tmp_path / "verdicts.csv"))
    assert [r["leading_end"] for r in back] == ["narrow", "blunt", "narrow", "blunt", "blunt"]
    assert back[2]["score"] == 3.0 and back[2]["line_phi"] == 3.0 and back[2]["measured_speed_mps"] == 0.51
    assert back[3]["rejected_frames"] == 2.0 and back[3]["true_grade"] == "severe"
    table = verdict_table(rows).splitlines()
    assert table[0].split()[-6:] == ["line_phi", "phi", "grade", "verdict", "truth", "reason"]
    assert "v (m/s)" in table[0] and "lead" in table[0] and table[4].endswith(
        "merged with a neighbour at the measuring point")
    assert "severe" in table[3] and "blunt" in table[2]


def test_a_crowded_lane_matches_each_verdict_to_its_own_fillet():
    """Fillets 0.43 s apart (closer than the match tolerance): a fillet without a verdict does not take its
    follower's, and a track's fragment that gave up early does not push the others along."""
    spawns = [Spawn(sim_id=i, lane=0, mesh="m", k=k, mass=20.0, line_speed=0.508, stamp=i * 0.4333,
                    spawn_x=-1.016) for i, k in enumerate((0.0, 100.0, 0.0))]

    def verdict(fillet_id, stamp, classification, phi):
        return Verdict(fillet_id=fillet_id, lane=0, stamp=stamp, classification=classification, grade="", phi=phi,
                       hu_term=0.1, solidity_term=0.01, nmdm=math.nan, mdm=math.nan, be=math.nan)

    rows = join(spawns, [verdict(7, 2.2, "unscored", math.nan), verdict(8, 2.4333, "woody", 3.0),
                         verdict(9, 2.8667, "normal", 14.0)])
    assert [(r["sim_id"], r["fillet_id"]) for r in rows] == [(0, 7), (1, 8), (2, 9)]
    rows = join(spawns, [verdict(8, 2.4333, "woody", 3.0), verdict(9, 2.8667, "normal", 14.0),
                         verdict(10, 3.2, "unscored", math.nan)])
    assert [(r["sim_id"], r["fillet_id"], r["verdict"]) for r in rows][:3] == [
        (0, "", "missing"), (1, 8, "woody"), (2, 9, "normal")]
    assert rows[3]["fillet_id"] == 10 and rows[3]["reason"] == "no spawned fillet matches"


def test_a_fillet_to_divert_without_a_gate_command_counts_as_not_diverted(tmp_path):
    """reject_gate sends no command for a verdict that came too late: the fillet passed, whatever its verdict."""
    spawns = [Spawn(sim_id=i, lane=i, mesh="m", k=100.0, mass=20.0, line_speed=2.032, stamp=0.0, spawn_x=-1.016)
              for i in range(3)]
    verdicts = [Verdict(fillet_id=10 + i, lane=i, stamp=0.5, classification="woody", grade="severe", phi=3.0,
                        hu_term=0.1, solidity_term=0.01, nmdm=math.nan, mdm=math.nan, be=math.nan, threshold=8.0,
                        score=3.0) for i in range(3)]
    rows = join(spawns, verdicts, gate_commands={(0, 10): 0.41, (2, 12): 0.38})
    assert [r["gate_command"] for r in rows] == ["sent", "none", "sent"]
    assert rows[0]["gate_margin_s"] == 0.41 and math.isnan(rows[1]["gate_margin_s"])
    assert gate_timing_line(rows) == "- the gate's timing margin (how long before its diverter had to open each " \
        "command was sent): least 0.380 s, median 0.395 s over 2 commands"
    assert [gate_missed(r, True) for r in rows] == [False, True, False]
    acc = accuracy(rows, divert_unscored=True)
    assert (acc.woody_diverted, acc.correct) == (2, 3) and math.isclose(acc.line_accuracy, 2 / 3)
    assert diversion_summary(rows, True) == ("line accuracy 66.7%, scored 100.0%; diverted 2 of 3 woody fillets; "
                                             f"1 not diverted ({GATE_MISSED_REASON}): fillets 11")
    assert GATE_MISSED_REASON in verdict_table(rows).splitlines()[2]
    text = build_report(read_csv(write_csv(rows, tmp_path / "verdicts.csv")), tmp_path).read_text()
    assert "line accuracy (every fillet; one without a verdict is not diverted): **66.7%**" in text
    assert f"- not diverted, {GATE_MISSED_REASON}: fillets 11" in text and "11 (woody, 3, late at the gate)" in text
    unknown = join(spawns, verdicts)  # no gate data (a verdict table alone): the verdict decides
    assert {r["gate_command"] for r in unknown} == {""} and accuracy(unknown).woody_diverted == 3


def test_a_top_camera_other_than_the_calibrated_one_is_noted():
    assert other_camera_note("default", "default") is None
    assert other_camera_note("/etc/woody/cameras/paper.yaml", "paper") is None  # a camera file by its name
    note = other_camera_note("config/cameras/realsense-d435.yaml", "default")
    assert note.startswith("the calibration's cuts were fitted on the 'default' top camera, not this run's "
                           "'realsense-d435'")
    assert resolved_calibration().top_camera == "default"  # the installed calibration does not name one


def test_a_line_speed_outside_the_calibrated_ones_is_noted_in_the_report(tmp_path):
    assert uncalibrated_speed_note(120.0, (90.0, 140.0)) is None and uncalibrated_speed_note(200.0, None) is None
    note = uncalibrated_speed_note(200.0, (90.0, 140.0))
    assert note.startswith("line speed 200 FPM is outside the 90..140 FPM the calibration's cuts were fitted on")
    assert calibrated_speeds({CALIBRATED_SPEEDS: "90..140"}) == (90.0, 140.0)
    assert calibrated_speeds({CALIBRATED_SPEEDS: "not recorded in the calibration"}) is None
    spawns = [Spawn(sim_id=i, lane=0, mesh="m", k=0.0, mass=20.0, line_speed=speed, stamp=2.0 * i, spawn_x=-1.0)
              for i, speed in enumerate((0.508, 1.016))]  # 100 and 200 FPM (a speed change)
    text = build_report(join(spawns, []), tmp_path, run_info={CALIBRATED_SPEEDS: "90..140"}).read_text()
    assert f"- {note}" in text and "100 FPM is outside" not in text
    assert "outside" not in build_report(join(spawns, []), tmp_path).read_text()  # the range is not known
