"""``runs.csv``, the table every sweep and calibration run writes: its name, columns, typed reader and writer.

One row per lane of a run (:func:`woody_experiments.experiment.evaluate_run`).
The reader gives every column its type (:data:`FLOAT_COLUMNS` as floats, an
empty cell as NaN; :data:`INT_COLUMNS` as ints; the rest as strings), the
writer formats floats to six significant digits and NaN as an empty cell, so
what it writes reads back to the same values.
"""

from __future__ import annotations

import csv
import io
import math
import os
from pathlib import Path

from woody_experiments.conditions import TIDY

FILE_NAME = "runs.csv"

RUN_COLUMNS = ["mesh", "k", "speed_fpm", "condition", "lane", "mass", "yaw_deg", "blunt_first", "scale", "phi",
               "hu_term", "solidity_term", "line_phi", "speed_mps", "leading_end", "turn_deg", "length_m", "rejected",
               "nmdm", "mdm", "be", "status", "reason"]
"""One row per lane: the run (mesh, k, speed, condition and how the fillet lay), the paper's Φ (NaN unless its
window closed cleanly), the line score with what the grader measured, the side view, and the verdict's status."""
FLOAT_COLUMNS = ("k", "speed_fpm", "mass", "yaw_deg", "blunt_first", "scale", "phi", "hu_term", "solidity_term",
                 "line_phi", "speed_mps", "turn_deg", "length_m", "rejected", "nmdm", "mdm", "be")
"""Numbers; an empty (or unreadable) cell reads as NaN."""
INT_COLUMNS = ("lane",)
STRING_COLUMNS = tuple(c for c in RUN_COLUMNS if c not in FLOAT_COLUMNS and c not in INT_COLUMNS)


def run_key(mesh: str, k: float, speed: float, mass: float, condition: str = TIDY) -> tuple:
    """A run's identity in ``runs.csv``: mesh, k, speed, the chain mass before any size scaling, condition."""
    return (mesh, round(float(k), 6), round(float(speed), 6), round(float(mass), 3), condition)


def row_key(row: dict) -> tuple:
    """The `run_key` of the run a lane row (as evaluated, or read back) belongs to: its mass is the scaled chain's
    (M·s³), so it is divided by the size scale, and a row without a scale or condition is of an unscaled, tidy run."""
    scale = float(row.get("scale") or math.nan)
    mass = float(row["mass"]) / (scale ** 3 if math.isfinite(scale) else 1.0)
    return run_key(row["mesh"], row["k"], row["speed_fpm"], mass, row.get("condition") or TIDY)


def read_runs(path: Path) -> list[dict]:
    """The rows of a runs.csv, typed per column; [] when the file does not exist. A row whose lane is not a
    whole number (a torn last line) is dropped; a column an older file lacks reads as NaN or ''."""
    path = Path(path)
    if not path.exists():
        return []
    rows = []
    with path.open(newline="") as fh:
        for raw in csv.DictReader(fh):
            try:
                row = {c: int(raw[c]) for c in INT_COLUMNS}
            except (KeyError, TypeError, ValueError):
                continue
            row.update({c: _float(raw.get(c)) for c in FLOAT_COLUMNS})
            row.update({c: raw.get(c) or "" for c in STRING_COLUMNS})
            rows.append(row)
    return rows


def _float(text: str | None) -> float:
    try:
        return float(text) if text else math.nan
    except ValueError:
        return math.nan


class RunsFile:
    """``runs.csv``, written by the client only: every write replaces the whole file atomically.

    The text is kept in memory and written to a temporary file that is
    fsync'ed and renamed over the old one, so a Ctrl-C or a kill at any moment
    leaves either the previous batch's file or the new one, never a torn row.
    """

    def __init__(self, path: Path, rows: list[dict]):
        self.path = Path(path)
        self._text = csv_text(rows, header=True)
        self._replace()

    def append(self, rows: list[dict]) -> None:
        self._text += csv_text(rows, header=False)
        self._replace()

    def _replace(self) -> None:
        tmp = self.path.with_name(self.path.name + ".tmp")
        with tmp.open("w", newline="") as fh:
            fh.write(self._text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, self.path)


def csv_text(rows: list[dict], header: bool) -> str:
    """Rows as CSV text in RUN_COLUMNS order (other keys, e.g. a run's trace, are left out)."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=RUN_COLUMNS, extrasaction="ignore")
    if header:
        writer.writeheader()
    for row in rows:
        writer.writerow({c: _cell(row.get(c, "")) for c in RUN_COLUMNS})
    return buffer.getvalue()


def _cell(value) -> object:
    if isinstance(value, float):
        return "" if math.isnan(value) else f"{value:.6g}"
    return value
