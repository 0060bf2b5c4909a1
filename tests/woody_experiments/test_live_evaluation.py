"""woody_experiments.live_evaluation: the grid, the conditions' woody run options, and the cells' verdicts counted as
the line handles them (the command end to end: tests/woody_tools/test_evaluate_command.py)."""

from __future__ import annotations

import csv

import pytest

from woody_experiments.live_evaluation import (
    CELL_COLUMNS,
    EVALUATION_CSV,
    Cell,
    cell_folder,
    cell_rows,
    condition_options,
    describe_condition,
    failures_by_reason,
    grid,
    reason_group,
    tally,
    woody_not_diverted,
    write_evaluation,
    write_run_record,
)
from woody_experiments.run_report import VERDICT_COLUMNS, write_csv
from woody_sim.line_conditions import LINE_PRESETS, longest_placed_length, mean_placed_length
from woody_sim.meshes import generate_fillet

LATE = "frames lost at the roller edge: the window closed {} px past the fillet's centroid"
MERGED = ("no clean frames around the measuring point (overhang 0.50 L): frames lost or merged with a neighbour "
          "({} rejected)")


def row(fillet_id: int | str, lane: int, mesh: str, k: float | str, verdict: str, reason: str = "",
        gate: str = "sent") -> dict:
    """One verdicts.csv row as woody run writes it: truth and true grade from k, none for a verdict nobody spawned."""
    truth = "" if k == "" else ("woody" if k >= 50 else "normal")
    grade = {"normal": "normal", "woody": "severe"}.get(verdict, "")
    true_grade = "" if k == "" else ("severe" if k >= 40 else "normal")
    return {"fillet_id": fillet_id, "lane": lane, "mesh": mesh, "k": k, "speed_fpm": 100.0, "verdict": verdict,
            "grade": grade, "truth": truth, "true_grade": true_grade, "reason": reason, "score": 5.0,
            "phi": 5.0, "gate_command": "" if verdict == "missing" else gate}


TIDY = Cell("tidy", 3, 100.0, 1)
CROWDED = Cell("crowded", 3, 100.0, 1)
ROWS = {
    TIDY: [row(0, 0, "seed0000", 0.0, "normal", gate="none"),  # passed: right
           row(1, 1, "seed0001", 100.0, "woody"),  # diverted: right
           row(2, 2, "seed0002", 100.0, "normal", gate="none")],  # graded against its stiffness: not diverted
    CROWDED: [row(3, 0, "seed0000", 100.0, "unscored", LATE.format(35)),  # unscored woody: diverted, right
              row(4, 1, "seed0001", 0.0, "unscored", LATE.format(12)),  # unscored normal: diverted, wrong
              row("", 2, "seed0002", 100.0, "missing", "no verdict was published for this fillet"),
              row(5, 0, "generated-0000", 100.0, "woody", gate="none"),  # too late for the gate
              row(6, 1, "", "", "unscored", MERGED.format(3))],  # a verdict nobody spawned
}


def write_cells(out, rows_by_cell=ROWS) -> None:
    for cell, rows in rows_by_cell.items():
        write_csv(rows, cell_folder(out, cell) / "verdicts.csv")
        write_run_record(out, cell, ["woody", "run"], 0, 12.0)


def test_a_cell_is_read_back_from_its_run_folders_name():
    for cell in (TIDY, CROWDED, Cell("gaps", 6, 130.0, 35), Cell("messy", 3, 82.5, 7)):
        assert Cell.from_name(cell.name) == cell
        assert cell.columns == {"run": cell.name, "condition": cell.condition, "seed": cell.seed,
                                "lanes": cell.lanes, "speed": cell.speed_fpm}
    with pytest.raises(ValueError, match="not a woody evaluate run folder name"):
        Cell.from_name("run-2026-12-02")


def test_the_grid_runs_seed_by_seed():
    cells = grid([1, 2], ["tidy", "gaps"], [3], [100.0, 130.0])
    assert [c.name for c in cells[:4]] == ["tidy-3lanes-100fpm-seed1", "tidy-3lanes-130fpm-seed1",
                                           "gaps-3lanes-100fpm-seed1", "gaps-3lanes-130fpm-seed1"]
    assert len(cells) == 8 and {c.seed for c in cells[4:]} == {2}


def test_crowded_and_gaps_set_their_spacing_from_the_mesh_set():
    meshes = [generate_fillet(s) for s in (0, 3)]
    messy = LINE_PRESETS["messy"]
    assert condition_options("tidy", meshes) == ["--line", "tidy"]
    crowded = condition_options("crowded", meshes)
    assert crowded[:4] == ["--line", "messy", "--lane-pitch", "0.12"] and crowded[4] == "--spacing"
    spacing = float(crowded[5])
    assert longest_placed_length(meshes, messy) <= spacing < longest_placed_length(meshes, messy) + 0.01
    assert spacing * 100 == pytest.approx(round(spacing * 100))  # whole centimetres
    gaps = float(condition_options("gaps", meshes)[5])
    assert gaps == pytest.approx(mean_placed_length(meshes, messy) + 0.02, abs=5e-4)
    assert describe_condition("messy") == "--line messy"
    assert describe_condition("gaps").startswith("--line messy --lane-pitch 0.12 --spacing S, S the mesh set's mean")


def test_reasons_lose_their_numbers_so_that_they_group():
    assert reason_group(LATE.format(35)) == reason_group(LATE.format(12.5)) == "frames lost at the roller edge"
    assert reason_group(MERGED.format(3)) == "no clean frames around the measuring point (overhang # L)"
    assert reason_group("track ended before the evaluation window closed; side view absent: frames lost (0.1 s)") \
        == "track ended before the evaluation window closed; side view absent"


def rows_of(out) -> list[dict]:
    return cell_rows(out, list(ROWS))


def test_rows_are_counted_as_the_line_handles_them(tmp_path):
    write_cells(tmp_path)
    rows = rows_of(tmp_path)
    assert (rows[0]["run"], rows[0]["condition"], rows[0]["lanes"], rows[0]["speed"]) == (TIDY.name, "tidy", 3, 100.0)
    t = tally(rows)
    assert (t.runs, t.fillets, t.meshes, t.extra, t.verdicts) == (2, 7, 4, 1, 7)
    assert (t.right, t.woody, t.woody_not_diverted, t.unscored, t.missing) == (3, 5, 3, 2, 1)
    assert [(r["run"], r["fillet_id"]) for r in woody_not_diverted(rows)] == [
        (TIDY.name, "2"), (CROWDED.name, ""), (CROWDED.name, "5")]


def test_failures_group_by_reason(tmp_path):
    write_cells(tmp_path)
    groups = {reason: len(rows) for reason, rows in failures_by_reason(rows_of(tmp_path))}
    assert groups == {"frames lost at the roller edge": 2, "graded normal, woody by its stiffness": 1,
                      "no verdict was published for this fillet": 1, "no gate command": 1,
                      "extra verdict (no clean frames around the measuring point (overhang # L))": 1}
    assert list(groups)[0] == "frames lost at the roller edge"  # the most frequent first


def test_the_evaluation_writes_its_tables_and_one_row_per_fillet(tmp_path):
    write_cells(tmp_path)
    cells = list(ROWS) + [Cell("tidy", 3, 100.0, 2)]  # the last one not run yet
    md, csv_path, summary = write_evaluation(tmp_path, cells, {"seeds": "1-2"})
    text = md.read_text()
    assert summary[0].startswith("| condition | lanes | FPM | runs | fillets | meshes | right on the line |")
    assert "| tidy | 3 | 100 | 1 | 3 | 3 | 66.7 % (2/3; 21–94 %) | 50.0 % (1/2; 9–91 %) |" in summary[2]
    assert summary[-1].startswith("| **all** | 3 | 100 | 2 | 7 | 4 | 42.9 % (3/7;")
    assert "| seeds | 1-2 |" in text and "\n".join(summary) in text
    assert f"| {CROWDED.name} | 5 | 0 | generated-0000 | 100 | woody | 5 | no gate command |" in text
    assert "| frames lost at the roller edge | 2 | 0 | 1 | 1 |" in text
    assert "| severe | 1 | 0 | 2 | 1 | 1 |" in text and "2 of 3 runs done, 0.4 min of wall time." in text
    assert "| tidy-3lanes-100fpm-seed2 | not run | no | runs/tidy-3lanes-100fpm-seed2/woody-run.log |" in text
    with csv_path.open(newline="") as handle:
        written = list(csv.DictReader(handle))
    assert csv_path.name == EVALUATION_CSV and list(written[0]) == CELL_COLUMNS + VERDICT_COLUMNS
    assert len(written) == 8 and written[3]["condition"] == "crowded" and written[3]["speed"] == "100"
    assert written[0]["phi"] == "5" and written[7]["truth"] == ""  # numbers as verdicts.csv has them; the extra
