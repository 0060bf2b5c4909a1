"""`woody sweep` end to end through the real CLI: rows, report, plots, resume, repair of a truncated runs.csv."""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import re
import subprocess
import sys
from pathlib import Path

import pytest

from woody_common.calibration import resolved_calibration, write_calibration
from woody_experiments import statistics, sweep_report, traces
from woody_experiments.runs_csv import RUN_COLUMNS

MESHES = "generated:2:7"
ARGS = ["sweep", "--meshes", MESHES, "--k", "0,100", "--speeds", "100", "--jobs", "2", "--traces"]


def _woody(*args: str) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-c", "import sys; from woody_tools.cli import main; sys.exit(main(sys.argv[1:]))", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300)  # a LocalCluster on a busy 2-core machine


def _rows(path: Path) -> list[dict]:
    with path.open(newline="") as fh:
        reader = csv.DictReader(fh)
        assert reader.fieldnames == RUN_COLUMNS
        return list(reader)


THRESHOLD = 12.34
"""The Φ threshold of the calibration the sweep is given (--calibration), not the installed one."""


def _calibration(tmp_path: Path) -> Path:
    """A calibration fitted (says its provenance) on this sweep's own meshes, with its own threshold."""
    installed = resolved_calibration()
    calibration = dataclasses.replace(installed, phi_threshold=THRESHOLD,
                                      provenance={**installed.provenance, "calibration_meshes": MESHES})
    return write_calibration(calibration, tmp_path / "calibration.yaml")


def test_sweep_refuses_a_calibration_it_cannot_read(tmp_path):
    result = _woody(*ARGS, "--out", str(tmp_path / "sweep"), "--calibration", str(tmp_path / "none.yaml"))
    assert result.returncode == 2
    assert result.stderr.strip().splitlines()[-1].startswith("woody sweep: ")
    assert "none.yaml: cannot read the calibration" in result.stderr


@pytest.mark.slow
def test_sweep_cli_rows_report_resume(tmp_path):
    out = tmp_path / "sweep"
    first = _woody(*ARGS, "--out", str(out), "--calibration", str(_calibration(tmp_path)))
    assert first.returncode == 0, first.stderr[-2000:]
    rows = _rows(out / "runs.csv")
    # 2 meshes x 2 k x 1 speed x 3 lanes
    assert len(rows) == 12
    keys = {(r["mesh"], float(r["k"]), float(r["speed_fpm"]), int(r["lane"])) for r in rows}
    assert keys == {(m, k, 100.0, lane) for m in ("generated-70000", "generated-70001") for k in (0.0, 100.0)
                    for lane in range(3)}
    _check_rows(rows)
    _check_report(out)
    _check_docs(out, tmp_path / "docs")
    _check_traces(out, rows, keys)
    _check_resume(out, keys)


def _check_rows(rows):
    """Every lane scored, side metrics on the centre lane only, stiff fillets keep their outline."""
    for r in rows:
        assert r["status"] == "scored", r
        assert math.isfinite(float(r["phi"])) and math.isfinite(float(r["hu_term"]))
        side = [r[c] for c in ("nmdm", "mdm", "be")]
        if int(r["lane"]) == 1:  # the side camera watches the centre lane
            assert all(v != "" for v in side), r
            assert 0.2 < float(r["nmdm"]) < 1.5
        else:
            assert all(v == "" for v in side), r
    # stiff fillets keep their outline: lower Φ and higher NMDM than flexible ones
    phi = {k: [float(r["phi"]) for r in rows if float(r["k"]) == k] for k in (0.0, 100.0)}
    assert sum(phi[0.0]) / 6 > sum(phi[100.0]) / 6


def _check_report(out):
    """results.md has every section and the paper's figures; the plots exist."""
    md = (out / "results.md").read_text()
    for heading in ("## Side view", "## Top view", "## Lanes", "## Targets", "## Throughput",
                    "## Classification per mesh set", "## Leave-one-out over the reference meshes"):
        assert heading in md
    for paper_figure in ("0.520", "0.783", "19.12 ± 5.67", "5.40 ± 2.54", "19.06 ± 5.53", "5.28 ± 2.56"):
        assert paper_figure in md
    assert "evaluations/min" in md
    # the grade stiffness by stiffness: every run of k = 0 graded one way or another
    assert "Three classes, tidy line, by stiffness" in md
    assert re.search(r"\| 0 \| normal \| \d+ \| \d+ \| \d+ \| [\d.]+ % \(\d+/2;", md)
    # the report grades with the --calibration file and names the mesh set from its provenance
    assert f"Φ threshold {THRESHOLD:g}" in md
    assert f"`{MESHES}`; 2 of these meshes are in that calibration set" in md
    assert "**PASS**" in md or "**MISS**" in md
    for name in sweep_report.PLOTS:
        assert (out / name).stat().st_size > 1000


def _check_docs(out, docs):
    """--docs: results.md keeps its hand-written discussion; the plots and the raw runs.csv are replaced."""
    (docs / "results").mkdir(parents=True)
    (docs / "results.md").write_text("old figures\n<!-- discussion -->\nwhat the misses mean\n")
    (docs / "results" / "runs.csv").write_text("stale\n")
    sweep_report.build(out, docs=docs)
    md = (docs / "results.md").read_text()
    assert "old figures" not in md and md.endswith("<!-- discussion -->\nwhat the misses mean\n")
    assert (docs / "results" / "runs.csv").read_text() == (out / "runs.csv").read_text()
    for name in sweep_report.PLOTS:
        assert (docs / "results" / name).stat().st_size > 1000


def _check_traces(out, rows, keys):
    # --traces: every scored lane's window frame by frame, and one plot per mesh and speed
    trace_rows = traces.join(out)
    runs = {(m, k) for m, k, _, _ in keys}
    assert sorted((out / traces.TRACE_DIR / "runs").glob("*.csv")) == sorted(
        traces.run_file(out, m, k, 100.0, float(rows[0]["mass"])) for m, k in runs)
    assert {(r["mesh"], r["k"], int(r["lane"])) for r in trace_rows} == {(m, k, lane) for m, k, _, lane in keys}
    for r in rows:
        window = [t for t in trace_rows if t["mesh"] == r["mesh"] and t["k"] == float(r["k"])
                  and int(t["lane"]) == int(r["lane"])]
        assert max(t["phi"] for t in window) == pytest.approx(float(r["phi"]), rel=1e-5)
        assert max(t["hu_term"] for t in window) == pytest.approx(float(r["hu_term"]), rel=1e-5)
        assert window[-1]["t_rel_s"] == 0.0
    for mesh in ("generated-70000", "generated-70001"):
        assert (out / traces.TRACE_DIR / f"{mesh}_100fpm.png").stat().st_size > 5000


def _check_resume(out, keys):
    # resumable: a second invocation runs nothing and leaves the rows alone
    before = (out / "runs.csv").read_text()
    second = _woody(*ARGS, "--out", str(out))
    assert second.returncode == 0, second.stderr[-2000:]
    assert "0 to go" in second.stderr
    assert (out / "runs.csv").read_text() == before

    # a truncated runs.csv (a killed sweep) is completed without duplicates
    lines = before.splitlines(keepends=True)
    (out / "runs.csv").write_text("".join(lines[:6]))  # header + 5 rows: one complete run, one partial
    third = _woody(*ARGS, "--out", str(out))
    assert third.returncode == 0, third.stderr[-2000:]
    assert "3 to go" in third.stderr
    again = _rows(out / "runs.csv")
    assert len(again) == 12
    assert {(r["mesh"], float(r["k"]), int(r["lane"])) for r in again} == {(m, k, lane) for m, k, _, lane in keys}

    # one top camera per folder: another camera is refused before anything runs
    other = _woody(*ARGS, "--out", str(out), "--top-camera", "paper")
    assert other.returncode == 2 and "use another --out" in other.stderr
    turned = _woody(*ARGS, "--out", str(out), "--yaw-sd", "13")
    assert turned.returncode == 2 and "--yaw-sd 0.0; use another --out for --yaw-sd 13" in turned.stderr

    # runs made with other physics (a folder from before it recorded its physics: the paper's chain) are not mixed in
    meta = json.loads((out / "sweep_meta.json").read_text())
    for invocation in meta["invocations"]:
        del invocation["physics"]
    (out / "sweep_meta.json").write_text(json.dumps(meta))
    older = _woody(*ARGS, "--out", str(out))
    assert older.returncode == 2 and "the physics 40 slices at 480 Hz, 20 iterations; use another --out" in older.stderr


def test_each_mesh_lies_turned_the_same_way_at_every_k_and_speed_with_yaw_sd():
    from woody_experiments.sweep import plan
    from woody_sim.meshes import mesh_yaw

    runs = plan(["a", "b"], [0.0, 100.0], [100.0, 130.0], 3, 20.0, yaw_sd=13.0)
    yaws = {name: {r.yaw_deg for r in runs if r.mesh == name} for name in ("a", "b")}
    assert all(len(v) == 1 for v in yaws.values()) and yaws["a"] != yaws["b"]
    assert yaws["a"] == {mesh_yaw("a", 13.0)} and mesh_yaw("a", 26.0) == 2 * mesh_yaw("a", 13.0)
    assert {r.yaw_deg for r in plan(["a"], [0.0], [100.0], 3, 20.0)} == {0.0}


def test_threshold_and_roc_helpers():
    normal, severe = [15.0, 18.0, 20.0], [5.0, 7.0, 9.0]
    t, bacc = statistics.best_threshold(normal, severe)
    assert 9.0 < t < 15.0 and bacc == 1.0
    assert statistics.roc(normal, severe)[2] == 1.0
    assert statistics.accuracy(normal, severe, 8.0)[0] == pytest.approx(5 / 6)
