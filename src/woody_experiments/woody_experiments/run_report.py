"""Verdict tables and the line report: ground truth joined with verdicts, plots, accuracy.

Plain module (no rclpy): `woody run` and `woody report` both build the same
table and report from lists of dicts, whether they came from live topics, a
bag or a CSV written earlier.
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from woody_common.calibration import camera_name
from woody_common.line import mps_to_fpm
from woody_experiments.line_grade import GRADES, true_grade

VERDICT_COLUMNS = [
    "fillet_id", "lane", "mesh", "k", "speed_fpm", "phi", "hu_term", "solidity_term",
    "nmdm", "mdm", "be", "verdict", "grade", "truth", "sim_id", "mass", "spawn_time", "verdict_time", "reason",
    "threshold", "score", "line_phi", "measured_speed_mps", "leading_end", "rejected_frames", "true_grade",
    "gate_command", "gate_margin_s",
]
"""Columns of verdicts.csv: the paper's twelve first, then what an analyst needs to audit a row: the score the
verdict used, the line score, the fillet's measured speed and leading end, the window frames rejected as merged
with a neighbour, the grade its stiffness should get (woody_experiments.line_grade.true_grade), and whether
reject_gate sent a command for it (GATE_SENT, GATE_NONE; empty when the gate's commands are not known) and how
long before the diverter had to open it was sent (s)."""
GATE_SENT = "sent"
GATE_NONE = "none"
NUMERIC_COLUMNS = {"k", "speed_fpm", "phi", "hu_term", "solidity_term", "nmdm", "mdm", "be", "mass", "spawn_time",
                   "verdict_time", "threshold", "score", "line_phi", "measured_speed_mps", "rejected_frames",
                   "gate_margin_s"}
UNSCORED_DIVERTED = "unscored fillets diverted"
"""Run setting (report.md's table, the bag's ``woody.run`` record): reject_gate's ``divert_unscored``."""

RECORDING = "recording"
"""Run setting: the messages in the run's bag and those its recorder lost, per topic
(`woody_bag.summary.recording_text`)."""

CALIBRATED_SPEEDS = "calibrated line speeds (FPM)"
"""Run setting: the lowest and highest line speed the calibration's cuts were fitted on, "LOW..HIGH"."""

OUTSIDE_GRADED = "fillets outside the calibration graded"
"""Run setting: True when the grader grades fillets measured outside the fitted range (else they are unscored)."""

MATCH_TOLERANCE_S = 0.6
"""A verdict belongs to a spawned fillet when it closes this close to the expected edge crossing."""


@dataclass(frozen=True)
class Spawn:
    """Ground truth of one spawned fillet (from /line/ground_truth)."""

    sim_id: int
    lane: int
    mesh: str
    k: float
    mass: float
    line_speed: float
    stamp: float
    spawn_x: float

    @property
    def expected_crossing(self) -> float:
        """Sim time at which the fillet's centre reaches the roller edge (x = 0)."""
        return self.stamp + abs(self.spawn_x) / max(self.line_speed, 1e-9)


@dataclass(frozen=True)
class Verdict:
    """One /grading/verdicts message, flattened, with its /grading/side_metrics when the side camera watched it."""

    fillet_id: int
    lane: int
    stamp: float
    classification: str
    grade: str
    phi: float
    hu_term: float
    solidity_term: float
    nmdm: float = float("nan")
    mdm: float = float("nan")
    be: float = float("nan")
    reason: str = ""
    threshold: float = float("nan")
    score: float = float("nan")
    """The score the classification used (line_phi, or phi with the paper's rule)."""
    line_phi: float = float("nan")
    line_fraction: float = float("nan")
    speed: float = float("nan")
    """The fillet's speed measured in the top image (m/s)."""
    leading_end: str = ""
    rejected_frames: int = 0


@dataclass(frozen=True)
class SideRecord:
    """One /grading/side_metrics message, flattened: the side view's metrics of one watched-lane fillet."""

    fillet_id: int
    lane: int
    nmdm: float
    mdm: float
    be: float
    reason: str = ""


def with_side(verdicts: Sequence[Verdict], sides: Iterable[SideRecord]) -> list[Verdict]:
    """The verdicts with their side metrics, paired by lane and fillet id; a side reason joins the verdict's."""
    by_fillet = {(s.lane, s.fillet_id): s for s in sides}
    out = []
    for verdict in verdicts:
        side = by_fillet.get((verdict.lane, verdict.fillet_id))
        if side is not None:
            reason = "; ".join(r for r in (verdict.reason, side.reason) if r)
            verdict = replace(verdict, nmdm=side.nmdm, mdm=side.mdm, be=side.be, reason=reason)
        out.append(verdict)
    return out


def truth_of(k: float, woody_k: float) -> str:
    """Ground-truth class of a fillet from its stiffness."""
    return "woody" if k >= woody_k else "normal"


def join(spawns: Sequence[Spawn], verdicts: Sequence[Verdict], woody_k: float = 50.0,
         gate_commands: Mapping[tuple[int, int], float] | None = None, sides: Iterable[SideRecord] = ()) -> list[dict]:
    """One row per spawned fillet (and per verdict nobody spawned), matched by lane and edge-crossing time.

    Per lane, the pairs minimise the total time difference (an assignment, not first come first served): on a
    crowded lane fillets cross the edge less than MATCH_TOLERANCE_S apart, and a fillet without a verdict must
    not take its neighbour's. Scored verdicts are matched first, the unscored ones to the fillets left.
    ``gate_commands`` maps (lane, fillet id) of every GateCommand the run published to its timing margin (s): a
    verdict's row says whether the gate acted on it (reject_gate sends none for a verdict that came too late to
    divert) and with how much time to spare; ``sides``
    fills in the watched lane's side metrics (:func:`with_side`)."""
    verdicts = with_side(verdicts, sides)
    pairs: dict[int, int] = {}
    for lane in sorted({s.lane for s in spawns}):
        for scored in (True, False):  # a scored verdict is stamped at the crossing; an unscored one when it gave up
            lane_spawns = [i for i, s in enumerate(spawns) if s.lane == lane and i not in pairs]
            lane_verdicts = [j for j, v in enumerate(verdicts) if v.lane == lane
                             and (v.classification in ("normal", "woody")) == scored]
            pairs.update(_match(spawns, lane_spawns, verdicts, lane_verdicts))
    used = set(pairs.values())
    order = sorted(range(len(spawns)), key=lambda i: (spawns[i].expected_crossing, spawns[i].lane))
    rows = [_row(spawns[i], verdicts[pairs[i]] if i in pairs else None, woody_k) for i in order]
    rows += [_row(None, v, woody_k) for j, v in enumerate(verdicts) if j not in used]
    if gate_commands is not None:
        for row in rows:
            if row["verdict"] != "missing":
                margin = gate_commands.get((row["lane"], row["fillet_id"]))
                row["gate_command"] = GATE_NONE if margin is None else GATE_SENT
                row["gate_margin_s"] = math.nan if margin is None else round(margin, 4)
    return rows


def _match(spawns: Sequence[Spawn], spawn_ids: list[int], verdicts: Sequence[Verdict],
           verdict_ids: list[int]) -> dict[int, int]:
    """Spawn index -> verdict index of one lane: the assignment of least total |verdict stamp - crossing|
    among pairs within MATCH_TOLERANCE_S."""
    if not spawn_ids or not verdict_ids:
        return {}
    import numpy as np
    from scipy.optimize import linear_sum_assignment

    dt = np.abs(np.array([[verdicts[j].stamp - spawns[i].expected_crossing for j in verdict_ids]
                          for i in spawn_ids]))
    cost = np.where(dt <= MATCH_TOLERANCE_S, dt, 1e6)
    rows, cols = linear_sum_assignment(cost)
    return {spawn_ids[r]: verdict_ids[c] for r, c in zip(rows, cols) if dt[r, c] <= MATCH_TOLERANCE_S}


def _row(spawn: Spawn | None, verdict: Verdict | None, woody_k: float) -> dict:
    nan = float("nan")
    row = {column: "" for column in VERDICT_COLUMNS}
    if spawn is not None:
        row.update(sim_id=spawn.sim_id, lane=spawn.lane, mesh=spawn.mesh, k=spawn.k, mass=spawn.mass,
                   speed_fpm=round(mps_to_fpm(spawn.line_speed), 3), spawn_time=round(spawn.stamp, 4),
                   truth=truth_of(spawn.k, woody_k), true_grade=true_grade(spawn.k))
    if verdict is None:
        row.update(fillet_id="", phi=nan, hu_term=nan, solidity_term=nan, nmdm=nan, mdm=nan, be=nan, threshold=nan,
                   score=nan, line_phi=nan, measured_speed_mps=nan, rejected_frames=nan,
                   verdict="missing", reason="no verdict was published for this fillet")
        return row
    row.update(fillet_id=verdict.fillet_id, lane=verdict.lane, phi=verdict.phi, hu_term=verdict.hu_term,
               solidity_term=verdict.solidity_term, nmdm=verdict.nmdm, mdm=verdict.mdm, be=verdict.be,
               verdict=verdict.classification, grade=verdict.grade, verdict_time=round(verdict.stamp, 4),
               threshold=verdict.threshold, score=verdict.score, line_phi=verdict.line_phi,
               measured_speed_mps=verdict.speed, leading_end=verdict.leading_end,
               rejected_frames=verdict.rejected_frames,
               reason=verdict.reason if verdict.reason else ("" if spawn else "no spawned fillet matches"))
    return row


def write_csv(rows: Iterable[dict], path: Path, columns: Sequence[str] = VERDICT_COLUMNS) -> Path:
    """The rows as a CSV of ``columns`` (verdicts.csv's by default), NaN as an empty cell."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=columns, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({key: _fmt(value) for key, value in row.items()})
    return path


def _fmt(value: object) -> object:
    if isinstance(value, float):
        return "" if math.isnan(value) else f"{value:.6g}"
    return value


def read_csv(path: Path) -> list[dict]:
    """Rows of a verdicts.csv, numbers parsed back (empty cells → NaN)."""
    numeric = NUMERIC_COLUMNS
    with Path(path).open(newline="") as handle:
        reader = csv.DictReader(handle)
        missing = {"fillet_id", "lane", "k", "phi", "verdict"} - set(reader.fieldnames or [])
        if missing:
            raise ValueError(f"{path}: not a verdict table (missing columns {sorted(missing)})")
        rows = []
        for raw in reader:
            row = dict(raw)
            for key in numeric & row.keys():
                row[key] = float(row[key]) if row[key] not in ("", None) else float("nan")
            row["lane"] = int(row["lane"]) if row.get("lane") not in ("", None) else -1
            rows.append(row)
    return rows


@dataclass(frozen=True)
class Accuracy:
    scored: int
    correct: int
    unscored: int
    missing: int
    confusion: dict[tuple[str, str], int]
    line_correct: int = 0
    woody: int = 0
    """Fillets woody by ground truth."""
    woody_diverted: int = 0
    """Of them, diverted: graded woody, or unscored while reject_gate diverts unscored fillets."""
    divert_unscored: bool = False

    @property
    def accuracy(self) -> float:
        """Over the scored fillets only."""
        return self.correct / self.scored if self.scored else float("nan")

    @property
    def total(self) -> int:
        return self.scored + self.unscored + self.missing

    @property
    def line_accuracy(self) -> float:
        """Over every fillet on the line: diverted (graded woody, or unscored with ``divert_unscored``) is right
        for a woody fillet, passed is right for a normal one; a fillet without a verdict passes."""
        return self.line_correct / self.total if self.total else float("nan")


def to_divert(row: dict, divert_unscored: bool) -> bool:
    """Whether reject_gate is to divert the row's fillet: graded woody, or unscored when it diverts those."""
    return row["verdict"] == "woody" or (divert_unscored and row["verdict"] not in ("normal", "woody", "missing"))


def gate_missed(row: dict, divert_unscored: bool) -> bool:
    """A fillet to divert for which the gate sent no command: its verdict came too late for the diverter."""
    return to_divert(row, divert_unscored) and row.get("gate_command") == GATE_NONE


def diverted(row: dict, divert_unscored: bool) -> bool:
    """Whether the row's fillet was diverted: to divert, and the gate acted on it (or the gate's commands are not
    known)."""
    return to_divert(row, divert_unscored) and not gate_missed(row, divert_unscored)


GATE_MISSED_REASON = "no gate command: the verdict came too late to divert it"


def accuracy(rows: Sequence[dict], divert_unscored: bool = False) -> Accuracy:
    """Accuracy of normal/woody verdicts against ground truth, over the scored fillets and over the whole line."""
    confusion = {(t, p): 0 for t in ("normal", "woody") for p in ("normal", "woody")}
    scored = correct = unscored = missing = line_correct = woody = woody_diverted = 0
    for row in rows:
        if not row.get("truth"):
            continue
        if row["verdict"] == "missing":
            missing += 1
        elif row["verdict"] not in ("normal", "woody"):
            unscored += 1
        else:
            scored += 1
            correct += row["verdict"] == row["truth"]
            confusion[(row["truth"], row["verdict"])] += 1
        out = diverted(row, divert_unscored)
        line_correct += out == (row["truth"] == "woody")
        woody += row["truth"] == "woody"
        woody_diverted += out and row["truth"] == "woody"
    return Accuracy(scored, correct, unscored, missing, confusion, line_correct, woody, woody_diverted,
                    divert_unscored)


def grade_confusion(rows: Sequence[dict]) -> dict[tuple[str, str], int]:
    """(true grade from k, grade published) -> fillets; a fillet without a grade counts under its verdict
    (unscored, missing) or as "no grade" (the paper's rule grades none)."""
    confusion: dict[tuple[str, str], int] = {}
    for row in rows:
        if not row.get("true_grade"):
            continue
        if row["verdict"] in ("normal", "woody"):
            graded = row.get("grade") or "no grade"
        else:
            graded = row["verdict"]
        key = (row["true_grade"], graded)
        confusion[key] = confusion.get(key, 0) + 1
    return confusion


def grade_confusion_lines(rows: Sequence[dict]) -> list[str]:
    """The three-class grade of the rows as Markdown: how the truth is set, the share graded right and the confusion
    matrix (truth rows, graded columns)."""
    confusion = grade_confusion(rows)
    graded = list(GRADES) + sorted({g for _, g in confusion} - set(GRADES))
    right = sum(n for (t, g), n in confusion.items() if t == g)
    total = sum(confusion.values())
    lines = ["Truth from the stiffness: normal k = 0, moderate 0 < k < 40, severe k >= 40.", "",
             f"- graded right: {right} of {total}" + (f" (**{right / total:.1%}**)" if total else ""), "",
             "| truth \\ graded | " + " | ".join(graded) + " |", "|---" * (len(graded) + 1) + "|"]
    for truth in GRADES:
        if any(t == truth for t, _ in confusion):
            lines.append(f"| {truth} | " + " | ".join(str(confusion.get((truth, g), 0)) for g in graded) + " |")
    return lines


def diversion_by_condition(rows: Sequence[dict], divert_unscored: bool) -> list[tuple[str, int, int, list[str]]]:
    """Per condition (line speed at spawn, leading end the grader measured): (condition, woody fillets, diverted,
    the missed ones as "fillet id (verdict, score)")."""
    groups: dict[str, list[dict]] = {}
    for row in rows:
        if row.get("truth") != "woody":
            continue
        end = row.get("leading_end") or "end unknown"
        speed = row.get("speed_fpm")
        key = f"{speed:g} FPM, {end} first" if isinstance(speed, float) else f"{end} first"
        groups.setdefault(key, []).append(row)
    out = []
    for key in sorted(groups):
        group = groups[key]
        missed = [f"{_fillet_name(r)} ({r['verdict']}, {_cell(r.get('score'))}"
                  + (", late at the gate)" if gate_missed(r, divert_unscored) else ")")
                  for r in group if not diverted(r, divert_unscored)]
        out.append((key, len(group), len(group) - len(missed), missed))
    return out


def diversion_summary(rows: Sequence[dict], divert_unscored: bool) -> str:
    """One line for the terminal: line accuracy, woody fillets diverted, and the fillets the gate missed."""
    acc = accuracy(rows, divert_unscored)
    missed = [_fillet_name(r) for r in rows if gate_missed(r, divert_unscored)]
    late = (f"; {len(missed)} not diverted ({GATE_MISSED_REASON}): fillets {', '.join(missed)}" if missed else "")
    return f"{accuracy_title(acc)}; diverted {acc.woody_diverted} of {acc.woody} woody fillets{late}"


def _fillet_name(row: dict) -> str:
    return str(row.get("fillet_id") if row.get("fillet_id") not in ("", None) else row.get("sim_id"))


def accuracy_title(acc: Accuracy) -> str:
    """Both accuracies, so an unscored woody fillet (not diverted) never hides behind a scored 100 %."""
    if not acc.scored and not (acc.unscored + acc.missing):
        return "no fillets with ground truth"
    scored = f"{acc.accuracy:.1%}" if acc.scored else "n/a"
    return f"line accuracy {acc.line_accuracy:.1%}, scored {scored}"


TABLE_COLUMNS = [("fillet_id", 9), ("lane", 4), ("mesh", 14), ("k", 5), ("speed_fpm", 9),
                 ("measured_speed_mps", 8), ("leading_end", 6), ("score", 6), ("line_phi", 8), ("phi", 6),
                 ("grade", 8), ("verdict", 8), ("truth", 6)]
"""The terminal table's columns and widths; the reason of an unscored or missing fillet follows the row."""
TABLE_HEADINGS = {"measured_speed_mps": "v (m/s)", "leading_end": "lead", "speed_fpm": "FPM"}


def verdict_table(rows: Sequence[dict], limit: int = 40, divert_unscored: bool = False) -> str:
    """A fixed-width table of the main columns for the terminal: the score, line score, measured speed and leading
    end of each verdict, its grade and, for a fillet without a normal/woody verdict or one the gate missed, why."""
    lines = ["  ".join(f"{TABLE_HEADINGS.get(c, c):>{w}}" for c, w in TABLE_COLUMNS) + "  reason"]
    for row in rows[:limit]:
        cells = [f"{_cell(row.get(c, ''))[:w]:>{w}}" for c, w in TABLE_COLUMNS]
        reason = row.get("reason", "") if row.get("verdict") not in ("normal", "woody") else ""
        if gate_missed(row, divert_unscored):
            reason = "; ".join(filter(None, (reason, GATE_MISSED_REASON)))
        lines.append("  ".join(cells) + (f"  {reason}" if reason else ""))
    if len(rows) > limit:
        lines.append(f"... {len(rows) - limit} more rows")
    return "\n".join(lines)


def _cell(value: object) -> str:
    if isinstance(value, float):
        return "-" if math.isnan(value) else f"{value:.3g}"
    return str("" if value is None else value)


def uncalibrated_speed_note(fpm: float, calibrated: tuple[float, float] | None, graded: bool = False) -> str | None:
    """The warning for a line speed outside the ``calibrated`` (lowest, highest) FPM of the grading cuts; None
    inside it or when the calibration does not record its speeds. ``graded``: the grader grades such fillets anyway
    (grade_outside_calibration) instead of leaving them unscored."""
    if calibrated is None or calibrated[0] <= fpm <= calibrated[1]:
        return None
    what = ("they are graded on extrapolated cuts, not validated at this speed" if graded
            else "fillets measured outside them are unscored, so diverted")
    return (f"line speed {fpm:g} FPM is outside the {calibrated[0]:g}..{calibrated[1]:g} FPM the calibration's cuts "
            f"were fitted on: {what}")


def other_camera_note(top_camera: str, calibrated_camera: str) -> str | None:
    """The warning for a run whose top camera (a preset or a camera file) is not the one the calibration's cuts
    were fitted on (Calibration.top_camera); None when it is."""
    camera = camera_name(top_camera)
    if camera == calibrated_camera:
        return None
    return (f"the calibration's cuts were fitted on the '{calibrated_camera}' top camera, not this run's "
            f"'{camera}': fit them on it with woody calibrate --top-camera (docs/real-camera.md)")


def calibrated_speeds(run_info: dict | None) -> tuple[float, float] | None:
    """The run's CALIBRATED_SPEEDS setting as (lowest, highest) FPM; None when the run does not record it."""
    try:
        low, high = (float(v) for v in str((run_info or {})[CALIBRATED_SPEEDS]).split(".."))
    except (KeyError, ValueError):
        return None
    return low, high


def speed_notes_of(rows: Sequence[dict], run_info: dict | None) -> list[str]:
    """A warning per line speed of the fillets (at their spawn) outside the calibrated speeds."""
    speeds = sorted({r["speed_fpm"] for r in rows if isinstance(r.get("speed_fpm"), float)
                     and math.isfinite(r["speed_fpm"])})
    graded = bool((run_info or {}).get(OUTSIDE_GRADED, False))
    return [note for note in (uncalibrated_speed_note(fpm, calibrated_speeds(run_info), graded) for fpm in speeds)
            if note]


def build_report(rows: Sequence[dict], out_dir: Path, *, title: str = "woody line run",
                 run_info: dict | None = None, notes: Sequence[str] = (), extra: Sequence[str] = ()) -> Path:
    """Write report.md and its PNG plots into ``out_dir``; returns the report path.

    ``notes`` (mesh files skipped or converted, where a truncated bag ends) and a warning per line
    speed outside the calibrated ones are listed at the top, so nothing left out of the figures goes
    unsaid; ``extra`` Markdown lines (the fillet pictures of woody_experiments.fillet_pictures) end the
    report.
    """
    import matplotlib

    matplotlib.use("Agg")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    divert_unscored = unscored_diverted(run_info)
    acc = accuracy(rows, divert_unscored)
    scored = [r for r in rows if r["verdict"] in ("normal", "woody") and r.get("k") != ""]
    _plot_phi(scored, out_dir / "phi_by_k_lane.png")
    side = [r for r in scored if isinstance(r.get("nmdm"), float) and not math.isnan(r["nmdm"])]
    _plot_nmdm(side, out_dir / "nmdm_by_k.png")
    _plot_confusion(acc, out_dir / "confusion.png")
    lines = [f"# {title}", ""]
    if run_info:
        lines += ["| setting | value |", "|---|---|"] + [f"| {k} | {v} |" for k, v in run_info.items()] + [""]
    notes = list(notes) + speed_notes_of(rows, run_info)
    lines += [f"- {note}" for note in notes] + ([""] if notes else [])
    lines += _markdown_body(rows, scored, side, acc) + _pointer_lines(out_dir) + list(extra)
    path = out_dir / "report.md"
    path.write_text("\n".join(lines))
    return path


def unscored_diverted(run_info: dict | None) -> bool:
    """Whether the run's reject_gate diverted unscored fillets (its setting in the run's table); False when the
    run does not say (a verdict table alone, an older bag): an unscored fillet then counts as passed."""
    value = (run_info or {}).get(UNSCORED_DIVERTED, False)
    return value is True or str(value).lower() == "true"


def _line_sections(rows: Sequence[dict], acc: Accuracy) -> list[str]:
    """Woody fillets diverted or missed per condition, and the three-class grade's confusion matrix."""
    rule = "graded woody, or unscored" + (" (reject_gate diverts unscored fillets)" if acc.divert_unscored
                                         else "; unscored ones pass (divert_unscored off or not recorded)")
    late = [_fillet_name(r) for r in rows if gate_missed(r, acc.divert_unscored)]
    lines = ["## Woody fillets diverted", "",
             f"- diverted {acc.woody_diverted} of {acc.woody} woody fillets (diverted: {rule}, and the gate sent "
             "its command in time)",
             *([f"- not diverted, {GATE_MISSED_REASON}: fillets {', '.join(late)}"] if late else []),
             f"- correct verdicts (normal/woody as the truth): {acc.correct} of {acc.total} fillets",
             gate_timing_line(rows), "",
             "| condition | woody fillets | diverted | missed (verdict, score) |", "|---|---|---|---|"]
    lines += [f"| {key} | {n} | {n_out} | {', '.join(missed) or '–'} |"
              for key, n, n_out, missed in diversion_by_condition(rows, acc.divert_unscored)]
    lines += ["", "## Three-class grade", "", *grade_confusion_lines(rows)]
    unscored = [f"{r.get('fillet_id') or r.get('sim_id')}: {r.get('reason') or r['verdict']}" for r in rows
                if r.get("truth") and r["verdict"] not in ("normal", "woody")]
    if unscored:
        lines += ["", "Without a normal/woody verdict: " + "; ".join(unscored)]
    return lines + [""]


def gate_timing_line(rows: Sequence[dict]) -> str:
    """The report's line on the gate's timing margin over the commands it sent (``gate_margin_s``)."""
    import numpy as np

    margins = [r["gate_margin_s"] for r in rows if isinstance(r.get("gate_margin_s"), float)
               and math.isfinite(r["gate_margin_s"])]
    if not margins:
        return "- the gate's timing margin: no gate command recorded"
    return (f"- the gate's timing margin (how long before its diverter had to open each command was sent): least "
            f"{min(margins):.3f} s, median {float(np.median(margins)):.3f} s over {len(margins)} command"
            + ("s" if len(margins) > 1 else ""))


def _groups(rows: Sequence[dict]) -> tuple[list[float], list[int]]:
    return sorted({float(r["k"]) for r in rows}), sorted({int(r["lane"]) for r in rows})


def _plot_phi(scored: Sequence[dict], path: Path) -> None:
    """Each fillet's score (the one its verdict used) beside its own reject cut, per stiffness and lane."""
    import matplotlib.pyplot as plt
    import numpy as np

    ks, lanes = _groups(scored)
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    width = 0.8 / max(len(lanes), 1)
    for j, lane in enumerate(lanes):
        for i, k in enumerate(ks):
            group = [r for r in scored if float(r["k"]) == k and int(r["lane"]) == lane]
            values = [graded_score(r) for r in group]
            x = i + (j - (len(lanes) - 1) / 2) * width
            ax.scatter(np.full(len(values), x), values, s=14, color=f"C{j}", label=f"lane {lane}" if i == 0 else None)
            cuts = [r["threshold"] for r in group if isinstance(r.get("threshold"), float)]
            ax.scatter(np.full(len(cuts), x), cuts, s=40, marker="_", color="k",
                       label="each fillet's reject cut (below: woody)" if i == j == 0 and cuts else None)
            if values:
                ax.hlines(np.mean(values), x - width / 2, x + width / 2, color=f"C{j}")
    ax.set_xticks(range(len(ks)), [f"k={k:g}" for k in ks])
    ax.set_ylabel("score the verdict used (line_phi, or Φ)")
    ax.set_title("score per stiffness and lane")
    if lanes:
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def graded_score(row: dict) -> float:
    """The score the row's verdict used (``score``), or the paper's Φ for a row that does not carry one."""
    score = row.get("score")
    return score if isinstance(score, float) and math.isfinite(score) else row["phi"]


def _plot_nmdm(side: Sequence[dict], path: Path) -> None:
    import matplotlib.pyplot as plt
    import numpy as np

    ks, _ = _groups(side)
    fig, ax = plt.subplots(figsize=(5.0, 3.6))
    for i, k in enumerate(ks):
        values = [r["nmdm"] for r in side if float(r["k"]) == k]
        ax.scatter(np.full(len(values), i), values, s=16, color="C3")
        if values:
            ax.hlines(np.mean(values), i - 0.3, i + 0.3, color="C3")
    ax.set_xticks(range(len(ks)), [f"k={k:g}" for k in ks])
    ax.set_ylabel("NMDM (side view)")
    ax.set_title("NMDM per stiffness (watched lane)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_confusion(acc: Accuracy, path: Path) -> None:
    import matplotlib.pyplot as plt
    import numpy as np

    fig, ax = plt.subplots(figsize=(4.2, 3.6))
    labels = ["normal", "woody"]
    matrix = np.array([[acc.confusion[(t, p)] for p in labels] for t in labels])
    ax.imshow(matrix, cmap="Blues")
    for (i, j), value in np.ndenumerate(matrix):
        ax.text(j, i, str(value), ha="center", va="center", fontsize=14)
    ax.set_xticks([0, 1], labels)
    ax.set_yticks([0, 1], labels)
    ax.set_xlabel(f"verdict (+{acc.unscored + acc.missing} unscored, not shown)" if acc.unscored + acc.missing
                  else "verdict")
    ax.set_ylabel("ground truth")
    ax.set_title(accuracy_title(acc), fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _markdown_body(rows: Sequence[dict], scored: Sequence[dict], side: Sequence[dict], acc: Accuracy) -> list[str]:
    ks, lanes = _groups(scored)
    line = f"**{acc.line_accuracy:.1%}**" if acc.total else "n/a"
    passed = ("an unscored one is diverted, one without a verdict" if acc.divert_unscored
              else "one without a verdict")
    lines = [
        "## Accuracy against ground truth", "",
        f"- line accuracy (every fillet; {passed} is not diverted): {line}",
        f"- scored fillets: {acc.scored}, correct: {acc.correct}, accuracy: "
        + (f"**{acc.accuracy:.1%}**" if acc.scored else "n/a"),
        f"- unscored (window never closed cleanly): {acc.unscored}; no verdict at all: {acc.missing}", "",
        "![confusion](confusion.png)", "", *_line_sections(rows, acc),
        "## Shape score Φ per stiffness and lane", "",
        "| k | lane | n | Φ mean ± sd | line_phi mean ± sd | Hu term | solidity term |",
        "|---|---|---|---|---|---|---|",
    ]
    for k in ks:
        for lane in lanes:
            group = [r for r in scored if float(r["k"]) == k and int(r["lane"]) == lane]
            if group:
                lines.append(f"| {k:g} | {lane} | {len(group)} | {_mean_sd([r['phi'] for r in group])} | "
                             f"{_mean_sd([r.get('line_phi', math.nan) for r in group])} | "
                             f"{_mean_sd([r['hu_term'] for r in group], 3)} | "
                             f"{_mean_sd([r['solidity_term'] for r in group], 4)} |")
    lines += ["", "![phi](phi_by_k_lane.png)", "", "## Side view (watched lane)", "",
              "| k | n | NMDM | MDM (px) | BE |", "|---|---|---|---|---|"]
    for k in _groups(side)[0]:
        group = [r for r in side if float(r["k"]) == k]
        lines.append(f"| {k:g} | {len(group)} | {_mean_sd([r['nmdm'] for r in group], 3)} | "
                     f"{_mean_sd([r['mdm'] for r in group], 1)} | {_mean_sd([r['be'] for r in group], 1)} |")
    lines += ["", "![nmdm](nmdm_by_k.png)", "", "## Verdicts", "", "```",
              verdict_table(rows, limit=200, divert_unscored=acc.divert_unscored), "```", ""]
    return lines


DOCS = Path(__file__).resolve().parents[3] / "docs"
"""woody's docs in the checkout the package runs from (absent in an installed copy without the repository)."""


def _pointer_lines(out_dir: Path) -> list[str]:
    """Where the report's terms and columns are defined, and how to watch the run in Foxglove (links relative to
    the report, so a report kept in the repository links the same on every machine)."""
    def doc(name: str) -> str:
        path = DOCS / name
        return f"[docs/{name}]({os.path.relpath(path, out_dir.resolve())})" if path.exists() else f"woody's docs/{name}"

    return ["## Terms and the recording", "",
            f"Every term above (Φ, line_phi, the cut, Hu and solidity terms, NMDM, MDM, BE, unscored) and every "
            f"column of `verdicts.csv` with its unit: {doc('verdicts.md')}. To watch the run, open `line.mcap` in "
            f"Foxglove (Open local file) and import the layout `docs/foxglove-layout.json`: {doc('foxglove.md')}.",
            ""]


def _mean_sd(values: Sequence[float], digits: int = 2) -> str:
    import numpy as np

    data = np.array([v for v in values if isinstance(v, float) and not math.isnan(v)])
    if data.size == 0:
        return "–"
    return f"{data.mean():.{digits}f} ± {data.std(ddof=1) if data.size > 1 else 0.0:.{digits}f}"
