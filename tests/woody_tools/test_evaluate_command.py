"""`woody evaluate` end to end on the smallest grid: one `woody run`, its tables, and a second call that resumes
without running it again (the counting: tests/woody_experiments/test_live_evaluation.py; refusals:
tests/bad_input/test_cli.py)."""

from __future__ import annotations

import csv
import os
import subprocess

import pytest

from woody_experiments.live_evaluation import CELL_COLUMNS
from woody_tools.processes import entry_point

pytestmark = pytest.mark.ros
"""Starts `woody evaluate`, which starts `woody run` and its nodes."""

GRID = ("--seeds", "1", "--conditions", "tidy", "--lanes", "3", "--speeds", "100", "--fillets", "3")
CELL = "tidy-3lanes-100fpm-seed1"


def evaluate(out, timeout: float = 120) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}
    return subprocess.run([entry_point("woody"), "evaluate", *GRID, "--out", str(out)], capture_output=True,
                          text=True, timeout=timeout, env=env, stdin=subprocess.DEVNULL)


def test_evaluate_runs_the_grid_writes_its_tables_and_resumes(tmp_path):
    out = tmp_path / "evaluation"
    first = evaluate(out)
    assert first.returncode == 0, first.stderr[-2000:]
    assert "woody evaluate: 1 of 1 runs to go (0 already done" in first.stderr
    assert f"woody evaluate: {CELL}: done, " in first.stderr
    assert first.stdout.startswith("| condition | lanes | FPM | runs | fillets | meshes | right on the line |")
    text = (out / "evaluation.md").read_text()
    assert "| tidy | 3 | 100 | 1 | 3 | " in text and "| **all** | 3 | 100 | 1 | 3 | " in text
    assert "| condition tidy | `woody run --line tidy` |" in text and "1 of 1 runs done" in text
    with (out / "evaluation.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) >= 3 and list(rows[0])[:len(CELL_COLUMNS)] == CELL_COLUMNS
    assert {(r["run"], r["condition"], r["seed"], r["lanes"], r["speed"]) for r in rows} == {
        (CELL, "tidy", "1", "3", "100")}
    record = (out / "runs" / CELL / "run.json").read_text()

    again = evaluate(out, timeout=60)
    assert again.returncode == 0, again.stderr[-2000:]
    assert "woody evaluate: 0 of 1 runs to go (1 already done" in again.stderr and CELL not in again.stderr
    assert (out / "runs" / CELL / "run.json").read_text() == record  # not run again
    assert (out / "evaluation.md").read_text() == text
