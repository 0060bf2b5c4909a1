"""The live line measured over a grid: `woody evaluate`'s cells, and their verdicts pooled and counted.

A cell is one `woody run` (one seed, line condition, lane count and line speed) into ``runs/<cell name>/``; the
verdicts.csv it leaves is the cell's record, so a cell with one is done. What the headless sweep cannot see shows
here: fillets that touch and merge, verdicts that come too late for the gate, tracks lost or split in two. The
rows of the cells are counted as the line handles them (woody_experiments.run_report.accuracy, with reject_gate
diverting unscored fillets as woody run's does), per condition, lanes and speed and over the grid, each share with
a 95 % Wilson interval, and the failures are grouped by their reason. Plain module (no rclpy).
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import product
from pathlib import Path

from woody_experiments.run_report import (
    GATE_MISSED_REASON,
    VERDICT_COLUMNS,
    accuracy,
    diverted,
    gate_missed,
    grade_confusion_lines,
    read_csv,
    write_csv,
)
from woody_experiments.statistics import share_text
from woody_sim.line_conditions import LINE_PRESETS, longest_placed_length, mean_placed_length

MESSY = "messy"
CROWDED = "crowded"
GAPS = "gaps"
LIVE_CONDITIONS = ("tidy", MESSY, CROWDED, GAPS)
"""The line conditions of a grid, each a set of `woody run` options (:func:`condition_options`)."""
SPACING_RULES = {
    CROWDED: "the longest placed fillet of the mesh set (woody run's overlap bound) rounded up to the cm: fillets "
             "of a lane come close but never overlap",
    GAPS: "the mesh set's mean placed length (each mesh's footprint box under the messy line's turns and sizes, "
          "averaged) + 0.02 m: a 2 cm gap between consecutive fillets of a lane on average, less or none between "
          "long or turned ones (a fillet that would overlap another waits for room at the spawn point)",
}
"""The conditions whose lanes are 0.12 m apart and whose in-lane spacing follows the mesh set: how it is set."""
CROWDED_LANE_PITCH_M = 0.12
"""Lane pitch of the crowded and gaps lines: 1-2 cm between neighbouring builtin fillets (0.10-0.11 m wide) lying
straight and centred; sized up, offset or turned, they touch."""
MEAN_GAP_M = 0.02
"""The gaps line's mean belt gap between consecutive fillets of a lane."""
DIVERT_UNSCORED = True
"""woody run's reject_gate diverts unscored fillets (the run setting run_report.UNSCORED_DIVERTED)."""

RUNS_DIR = "runs"
VERDICTS = "verdicts.csv"
RUN_RECORD = "run.json"
"""In a cell's folder: the `woody run` command, its exit code and wall time, written when the run ends."""
RUN_LOG = "woody-run.log"
"""In a cell's folder: what its `woody run` printed."""
EVALUATION_MD = "evaluation.md"
EVALUATION_CSV = "evaluation.csv"
CELL_COLUMNS = ["run", "condition", "seed", "lanes", "speed"]
"""Columns evaluation.csv puts before verdicts.csv's: the cell's name, condition, seed, lane count and line speed
(FPM)."""


CELL_NAME = re.compile(r"([a-z]+)-(\d+)lanes-([0-9.]+)fpm-seed(\d+)")
"""A run folder's name (:attr:`Cell.name`)."""


@dataclass(frozen=True)
class Cell:
    """One `woody run` of the grid."""

    condition: str
    lanes: int
    speed_fpm: float
    seed: int

    @property
    def name(self) -> str:
        return f"{self.condition}-{self.lanes}lanes-{self.speed_fpm:g}fpm-seed{self.seed}"

    @classmethod
    def from_name(cls, name: str) -> Cell:
        """The cell whose run folder is ``name`` (:attr:`name`)."""
        match = CELL_NAME.fullmatch(name)
        if match is None:
            raise ValueError(f"not a woody evaluate run folder name: {name!r}")
        condition, lanes, speed, seed = match.groups()
        return cls(condition, int(lanes), float(speed), int(seed))

    @property
    def columns(self) -> dict[str, object]:
        """The cell's CELL_COLUMNS, as evaluation.csv carries them."""
        return dict(zip(CELL_COLUMNS, (self.name, self.condition, self.seed, self.lanes, self.speed_fpm)))

    @property
    def group(self) -> tuple[str, int, float]:
        """What the summary pools over: every seed of a condition, lane count and speed."""
        return self.condition, self.lanes, self.speed_fpm


def grid(seeds: Sequence[int], conditions: Sequence[str], lanes: Sequence[int], speeds: Sequence[float]) -> list[Cell]:
    """Every cell, seed by seed: a grid cut short holds about as many seeds of each condition, lanes and speed."""
    return [Cell(condition, n, speed, seed) for seed, condition, n, speed in product(seeds, conditions, lanes, speeds)]


def spacing_m(condition: str, meshes: list) -> float | None:
    """The in-lane spacing of a condition for the mesh set (woody_sim FilletMesh); None: woody run's default."""
    messy = LINE_PRESETS[MESSY]
    if condition == CROWDED:
        return math.ceil(round(longest_placed_length(meshes, messy) * 100, 6)) / 100
    if condition == GAPS:
        return round(mean_placed_length(meshes, messy) + MEAN_GAP_M, 3)
    return None


def _options(condition: str, spacing: str | None) -> list[str]:
    if spacing is None:
        return ["--line", condition]
    return ["--line", MESSY, "--lane-pitch", f"{CROWDED_LANE_PITCH_M:g}", "--spacing", spacing]


def condition_options(condition: str, meshes: list) -> list[str]:
    """The `woody run` options that make the condition's line for the mesh set."""
    spacing = spacing_m(condition, meshes)
    return _options(condition, None if spacing is None else f"{spacing:g}")


def describe_condition(condition: str) -> str:
    """The condition's `woody run` options for a help text, S standing for a spacing set by its rule."""
    rule = SPACING_RULES.get(condition)
    options = " ".join(_options(condition, "S" if rule else None))
    return f"{options}, S {rule}" if rule else options


def cell_folder(out: Path, cell: Cell) -> Path:
    return Path(out) / RUNS_DIR / cell.name


def is_done(out: Path, cell: Cell) -> bool:
    return (cell_folder(out, cell) / VERDICTS).exists()


def write_run_record(out: Path, cell: Cell, command: Sequence[str], exit_code: int, wall_s: float) -> None:
    record = {"command": list(command), "exit_code": exit_code, "wall_s": round(wall_s, 1)}
    (cell_folder(out, cell) / RUN_RECORD).write_text(json.dumps(record, indent=2))


def run_record(out: Path, cell: Cell) -> dict | None:
    """The cell's RUN_RECORD; None before its run ended."""
    path = cell_folder(out, cell) / RUN_RECORD
    return json.loads(path.read_text()) if path.exists() else None


def cell_rows(out: Path, cells: Sequence[Cell]) -> list[dict]:
    """The verdicts.csv rows of every done cell, the cell's columns (CELL_COLUMNS) added."""
    rows = []
    for cell in cells:
        if is_done(out, cell):
            rows += [{**cell.columns, **row} for row in read_csv(cell_folder(out, cell) / VERDICTS)]
    return rows


@dataclass(frozen=True)
class Tally:
    """Rows of some runs counted as the line handled them."""

    runs: int
    fillets: int
    """Spawned fillets (with ground truth)."""
    meshes: int
    right: int
    """Woody fillets diverted and normal ones passed (run_report.Accuracy.line_correct)."""
    woody: int
    woody_not_diverted: int
    unscored: int
    missing: int
    """Spawned fillets without a verdict."""
    extra: int
    """Verdicts no spawned fillet matches."""

    @property
    def verdicts(self) -> int:
        return self.fillets - self.missing + self.extra


def tally(rows: Sequence[dict]) -> Tally:
    acc = accuracy(rows, DIVERT_UNSCORED)
    spawned = [r for r in rows if r.get("truth")]
    return Tally(runs=len({r["run"] for r in rows}), fillets=acc.total, meshes=len({r["mesh"] for r in spawned}),
                 right=acc.line_correct, woody=acc.woody, woody_not_diverted=acc.woody - acc.woody_diverted,
                 unscored=acc.unscored, missing=acc.missing, extra=len(rows) - len(spawned))


NUMBER = re.compile(r"\d+(?:\.\d+)?")


def reason_group(reason: str) -> str:
    """A reason without its particulars, so that alike ones group: the head of each "; "-joined part (before its
    ": "), numbers left in it as "#"."""
    heads = (part.split(": ", 1)[0].strip() for part in reason.split("; "))
    return "; ".join(NUMBER.sub("#", head) for head in heads if head)


def failure(row: dict) -> str | None:
    """Why the row is not a fillet graded and handled right, None for one that is: a scored fillet graded against
    its stiffness, the reason's group (:func:`reason_group`) of an unscored or missing one or of a verdict no fillet
    matches, and the gate's missed command."""
    verdict, truth = row["verdict"], row.get("truth")
    why = []
    if not truth:
        why.append(f"extra verdict ({reason_group(row.get('reason') or verdict)})")
    elif verdict not in ("normal", "woody"):
        why.append(reason_group(row.get("reason") or verdict))
    elif verdict != truth:
        why.append(f"graded {verdict}, {truth} by its stiffness")
    if gate_missed(row, DIVERT_UNSCORED):
        why.append(reason_group(GATE_MISSED_REASON))
    return "; ".join(why) or None


def failures_by_reason(rows: Sequence[dict]) -> list[tuple[str, list[dict]]]:
    """(reason group, its rows), the most frequent first."""
    groups: dict[str, list[dict]] = {}
    for row in rows:
        reason = failure(row)
        if reason is not None:
            groups.setdefault(reason, []).append(row)
    return sorted(groups.items(), key=lambda item: (-len(item[1]), item[0]))


def woody_not_diverted(rows: Sequence[dict]) -> list[dict]:
    return [r for r in rows if r.get("truth") == "woody" and not diverted(r, DIVERT_UNSCORED)]


SUMMARY_HEADER = ["| condition | lanes | FPM | runs | fillets | meshes | right on the line | woody not diverted | "
                  "unscored | missing | extra verdicts |", "|---" * 11 + "|"]


def summary_lines(rows: Sequence[dict], cells: Sequence[Cell]) -> list[str]:
    """The summary table: a row per condition, lanes and speed of the grid, and the whole grid."""
    lines = list(SUMMARY_HEADER)
    for condition, lanes, speed in dict.fromkeys(c.group for c in cells):
        group = [r for r in rows if (r["condition"], r["lanes"], r["speed"]) == (condition, lanes, speed)]
        lines.append(_summary_row(f"{condition} | {lanes} | {speed:g}", tally(group)))
    lanes = ", ".join(str(n) for n in dict.fromkeys(c.lanes for c in cells))
    speeds = ", ".join(f"{s:g}" for s in dict.fromkeys(c.speed_fpm for c in cells))
    return lines + [_summary_row(f"**all** | {lanes} | {speeds}", tally(rows))]


def _summary_row(label: str, t: Tally) -> str:
    shares = (share_text(t.right, t.fillets), share_text(t.woody_not_diverted, t.woody),
              share_text(t.unscored, t.fillets), share_text(t.missing, t.fillets), share_text(t.extra, t.verdicts))
    return f"| {label} | {t.runs} | {t.fillets} | {t.meshes} | " + " | ".join(shares) + " |"


def _cell_text(value: object) -> str:
    if isinstance(value, float):
        return "–" if math.isnan(value) else f"{value:.3g}"
    return str(value)


def _not_diverted_lines(rows: Sequence[dict]) -> list[str]:
    missed = woody_not_diverted(rows)
    if not missed:
        return ["None.", ""]
    lines = ["| run | fillet | lane | mesh | k | verdict | score | why |", "|---" * 8 + "|"]
    lines += [f"| {r['run']} | {r.get('fillet_id') or '–'} | {r['lane']} | {r['mesh']} | {_cell_text(r['k'])} | "
              f"{r['verdict']} | {_cell_text(r.get('score', math.nan))} | {failure(r)} |" for r in missed]
    return lines + [""]


def _failure_lines(rows: Sequence[dict]) -> list[str]:
    groups = failures_by_reason(rows)
    if not groups:
        return ["None.", ""]
    lines = ["| reason | rows | woody not diverted | normal diverted | runs |", "|---" * 5 + "|"]
    for reason, group in groups:
        woody_passed = sum(r.get("truth") == "woody" and not diverted(r, DIVERT_UNSCORED) for r in group)
        normal_diverted = sum(r.get("truth") == "normal" and diverted(r, DIVERT_UNSCORED) for r in group)
        lines.append(f"| {reason} | {len(group)} | {woody_passed} | {normal_diverted} | "
                     f"{len({r['run'] for r in group})} |")
    return lines + [""]


def _run_lines(out: Path, cells: Sequence[Cell]) -> list[str]:
    """How the grid's runs went: done, wall time, and every run that failed or is still to do."""
    records = {cell: run_record(out, cell) for cell in cells}
    done = [c for c in cells if is_done(out, c)]
    wall = sum(r["wall_s"] for c, r in records.items() if r and c in done)
    lines = [f"{len(done)} of {len(cells)} runs done, {wall / 60:.1f} min of wall time.", ""]
    failed = [c for c in cells if (records[c] or {}).get("exit_code", 0) != 0 or not is_done(out, c)]
    if failed:
        lines += ["| run | woody run's exit code | verdicts.csv | log |", "|---" * 4 + "|"]
        lines += [f"| {c.name} | {(records[c] or {}).get('exit_code', 'not run')} | "
                  f"{'yes' if is_done(out, c) else 'no'} | {RUNS_DIR}/{c.name}/{RUN_LOG} |" for c in failed]
        lines.append("")
    return lines


def write_evaluation(out: Path, cells: Sequence[Cell], settings: dict[str, object]) -> tuple[Path, Path, list[str]]:
    """Write EVALUATION_MD and EVALUATION_CSV over the done cells; returns their paths and the summary table."""
    out = Path(out)
    rows = cell_rows(out, cells)
    csv_path = write_csv(rows, out / EVALUATION_CSV, columns=CELL_COLUMNS + VERDICT_COLUMNS)
    summary = summary_lines(rows, cells)
    lines = ["# woody evaluate: the live line", "", "| setting | value |", "|---|---|",
             *(f"| {key} | {value} |" for key, value in settings.items()), "",
             "Every fillet counts as the line handled it: right is a woody fillet diverted or a normal one passed; "
             "reject_gate diverts an unscored fillet, and a fillet to divert whose verdict came too late for the gate "
             "is not diverted. Missing: spawned, no verdict (passed); extra: a verdict no spawned fillet matches, as "
             "a share of the verdicts. 95 % Wilson intervals over fillets; the fillets of one run share its line and "
             "its neighbours, so the intervals are a little narrow.", "",
             "## Per condition, lanes and speed", "", *summary, "",
             "## Woody fillets not diverted", "", *_not_diverted_lines(rows),
             "## Failures by reason", "",
             "Every row not graded and handled right, by the head of its reason (numbers as #).", "",
             *_failure_lines(rows),
             "## Three-class grade, every run", "", *grade_confusion_lines(rows), "",
             "## Runs", "", *_run_lines(out, cells)]
    md_path = out / EVALUATION_MD
    md_path.write_text("\n".join(lines))
    return md_path, csv_path, summary
