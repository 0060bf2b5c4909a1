"""`woody report` never overwrites its input; a failed `woody run` can be retried as typed; a line speed outside
the calibrated ones is said at the start and in report.md; `woody sweep --out` and `woody calibrate --out` naming a
file are one line; a bad `woody evaluate` option, an --out of other settings and a cell woody run would refuse are
one line before any run."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest
from conftest import REPO

from bad_input.conftest import assert_one_clear_line, run_entries, run_entry
from woody_tools.processes import entry_point

pytestmark = pytest.mark.ros
"""Starts `woody` and, for `woody run`, every node entry point."""

SAMPLE = REPO / "bags" / "sample"


def woody(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}
    return subprocess.run([entry_point("woody"), *args], capture_output=True, text=True, timeout=timeout, env=env,
                          stdin=subprocess.DEVNULL)


def run_with_a_cut_bag(tmp_path: Path) -> Path:
    """A run folder (the sample's files) whose bag was cut short after the run wrote its verdicts."""
    run = tmp_path / "run"
    run.mkdir()
    for name in ("verdicts.csv", "report.md"):
        shutil.copy(SAMPLE / name, run / name)
    data = (SAMPLE / "line.mcap").read_bytes()
    (run / "line.mcap").write_bytes(data[:int(len(data) * 0.6)])
    return run


def test_a_report_of_a_cut_bag_leaves_the_runs_own_files_alone(tmp_path):
    run = run_with_a_cut_bag(tmp_path)
    before = {name: (run / name).read_bytes() for name in ("verdicts.csv", "report.md")}
    result = woody("report", str(run / "line.mcap"), timeout=120)
    assert result.returncode == 0, result.stderr
    assert {name: (run / name).read_bytes() for name in before} == before
    out = run / "line-report"
    assert result.stdout.strip() == f"report: {out / 'report.md'}"
    graded = [row for row in (out / "verdicts.csv").read_text().splitlines() if ",missing," not in row]
    assert len(graded) < len(before["verdicts.csv"].decode().splitlines())  # the readable part only
    assert "the bag ends early" in (out / "report.md").read_text()

    again = woody("report", str(run / "line.mcap"), "--out", str(tmp_path / "elsewhere"), timeout=120)
    assert again.returncode == 0 and (tmp_path / "elsewhere" / "report.md").exists(), again.stderr


@pytest.mark.parametrize("source", ["line.mcap", "verdicts.csv"])
def test_a_report_into_the_sources_folder_is_refused(tmp_path, source):
    run = run_with_a_cut_bag(tmp_path)
    before = {p.name: p.read_bytes() for p in run.iterdir()}
    result = woody("report", str(run / source), "--out", f"{run}/.", timeout=120)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert lines[0].startswith("woody report: --out ") and f"is the folder of {source}" in lines[0]
    assert {p.name: p.read_bytes() for p in run.iterdir()} == before


def bad_calibration(tmp_path: Path) -> Path:
    """A calibration woody run reads but the grader refuses (its severe cut above the reject cut)."""
    import yaml

    data = yaml.safe_load((REPO / "config" / "calibration.yaml").read_text())
    grader = data["/**/grader"]["ros__parameters"]
    grader["severe_threshold"], grader["line_threshold"] = grader["line_threshold"], grader["severe_threshold"]
    path = tmp_path / "bad-calibration.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_a_failed_run_that_graded_nothing_can_be_retried_as_typed(tmp_path):
    out = tmp_path / "run"
    failed = woody("run", "--fillets", "3", "--out", str(out), "--calibration", str(bad_calibration(tmp_path)))
    assert failed.returncode == 1, failed.stderr[-2000:]
    assert "node 'grader' exited with code 2" in failed.stderr
    assert (f"woody run: nothing was graded: the run's bag and logs are in {out / 'failed'}/, and the same command "
            "can run again") in failed.stderr
    assert (out / "failed" / "line.mcap").exists() and (out / "failed" / "logs" / "grader.log").exists()
    assert f"last lines of {out / 'failed' / 'logs' / 'grader.log'}" in failed.stderr

    retried = woody("run", "--fillets", "3", "--out", str(out))
    assert retried.returncode == 0, retried.stderr[-2000:]
    assert len((out / "verdicts.csv").read_text().splitlines()) == 1 + 3
    refused = woody("run", "--fillets", "3", "--out", str(out), timeout=120)  # a run that graded is kept
    assert refused.returncode == 2 and "already holds a run (line.mcap); pass --force" in refused.stderr


def test_a_speed_outside_the_calibrated_ones_is_warned_about_at_the_start_and_in_the_report(tmp_path):
    out = tmp_path / "run"
    result = woody("run", "--fillets", "3", "--speed-fpm", "200", "--out", str(out))
    assert result.returncode == 0, result.stderr[-2000:]
    warning = ("line speed 200 FPM is outside the 90..140 FPM the calibration's cuts were fitted on: fillets "
               "measured outside them are unscored, so diverted")
    first = [line for line in result.stderr.splitlines() if not line.startswith("pybullet build time")][0]
    assert first == f"woody run: {warning}"  # before the line starts
    report = (out / "report.md").read_text()
    assert f"- {warning}" in report and "| calibrated line speeds (FPM) | 90..140 |" in report
    again = woody("report", str(out / "line.mcap"), timeout=120)  # the bag carries it too
    assert again.returncode == 0 and f"- {warning}" in (out / "line-report" / "report.md").read_text()


def test_a_sweep_out_that_is_a_file_is_one_line_and_leaves_the_file(tmp_path):
    (tmp_path / "notes.txt").write_text("mine\n")
    for out, why in (("notes.txt", "File exists"), ("notes.txt/sweep", "Not a directory")):
        outcome = run_entry("woody", "sweep", "--meshes", "generated:1", "--out", out, domain=None, cwd=tmp_path)
        assert_one_clear_line(outcome, "woody sweep", f"--out {out}: cannot make the folder ({why})")
    assert [p.name for p in tmp_path.iterdir()] == ["notes.txt"] and (tmp_path / "notes.txt").read_text() == "mine\n"


def test_a_calibrate_out_that_is_a_file_is_one_line_before_any_work(tmp_path):
    (tmp_path / "notes.txt").write_text("mine\n")
    for out in ("notes.txt", "notes.txt/cal"):
        outcome = run_entry("woody", "calibrate", "--skip-physics", "--out", out, domain=None, cwd=tmp_path)
        assert_one_clear_line(outcome, "woody calibrate", f"--out {out}: notes.txt is not a folder")
    assert [p.name for p in tmp_path.iterdir()] == ["notes.txt"] and (tmp_path / "notes.txt").read_text() == "mine\n"


EVALUATE_REFUSALS = {  # `woody evaluate` options: refused before any run starts or --out is made
    ("--seeds", "3-1"): "--seeds must be like 1-8 or 1,2,3 with seeds 0..2147483647, got '3-1'",
    ("--seeds", "0-20000"): "--seeds must name at most 10000 seeds, got '0-20000'",
    ("--conditions", "tidy,rainy"): "--conditions must be among tidy,messy,crowded,gaps, got 'tidy,rainy'",
    ("--lanes", "3,7"): "--lanes: every lane count must be a whole number 1..6, got 7",
    ("--speeds", "100,500"): "--speeds: every speed must be within 1..400 FPM, got 500",
    ("--k=0,nan",): "--k: every k must be a finite number >= 0, got nan",
    ("--fillets", "0"): "--fillets must be 1..100000, got 0",
    ("--timeout", "nan"): "--timeout must be a positive number of seconds, got nan",
    ("--jobs", "0"): "--jobs must be at least 1, got 0",
    ("--meshes", "/no/such/meshes"): "--meshes: mesh spec '/no/such/meshes': not 'builtin', 'generated:N[:SEED]', "
                                     "a folder or a mesh file",
}


def test_bad_evaluate_options_are_one_line_and_make_no_folder():
    commands = [("woody", "evaluate", "--out", "evaluation", *options) for options in EVALUATE_REFUSALS]
    for outcome, message in zip(run_entries(commands, None, workers=2), EVALUATE_REFUSALS.values()):
        assert assert_one_clear_line(outcome, "woody evaluate") == f"woody evaluate: {message}"
        assert list(outcome.cwd.iterdir()) == []


def test_an_evaluate_out_of_other_settings_or_a_file_is_one_line_and_left_alone(tmp_path):
    (tmp_path / "evaluation").mkdir()
    (tmp_path / "evaluation" / "evaluate.json").write_text('{"fillets": 6, "meshes": "builtin", "k": [0.0, 100.0]}')
    (tmp_path / "notes.txt").write_text("mine\n")
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    refusals = {("--out", "evaluation", "--fillets", "12"): "--out evaluation holds runs with --fillets 6; use "
                                                             "another --out for --fillets 12",
                ("--out", "evaluation", "--k", "0,20"): "--out evaluation holds runs with --k 0,100; use another "
                                                        "--out for --k 0,20",
                ("--out", "notes.txt/evaluation"): "--out notes.txt/evaluation: notes.txt is not a folder"}
    for options, message in refusals.items():
        outcome = run_entry("woody", "evaluate", "--fillets", "6", *options, domain=None, cwd=tmp_path)
        assert assert_one_clear_line(outcome, "woody evaluate") == f"woody evaluate: {message}"
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == before


def test_an_evaluate_cell_woody_run_would_refuse_is_one_line_before_any_run(tmp_path):
    import trimesh

    (tmp_path / "meshes").mkdir()
    trimesh.creation.box(extents=(0.11, 0.06, 0.02)).export(tmp_path / "meshes" / "short.obj")  # gaps: 0.138 m apart
    outcome = run_entry("woody", "evaluate", "--meshes", str(tmp_path / "meshes"), "--conditions", "tidy,gaps",
                        "--out", "evaluation", domain=None)
    assert assert_one_clear_line(outcome, "woody evaluate") == (
        "woody evaluate: woody run refuses the gaps line at 3 lanes and 100 FPM: --spacing must be within 0.15..10 m "
        "(below 0.15 m every fillet overlaps the next), got 0.138")
    assert list(outcome.cwd.iterdir()) == []
