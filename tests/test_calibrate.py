"""`woody calibrate --loo`: the leave-one-mesh-out check's wiring (runs planned, folds reported, refusals)."""

from __future__ import annotations

import json
import subprocess
import sys

from woody_common.calibration import load_calibration
from woody_tools import calibrate

PHI = {"seed0000": (20.0, 4.0), "seed0001": (18.0, 5.0), "seed0002": (16.0, 12.5)}
"""Per mesh (normal, severe) Φ: seed0002's stiff Φ sits above what the others call woody."""


def fake_evaluate(runs, spec, jobs, desc):
    rows = []
    for run in runs:
        phi = PHI[run.mesh][0 if run.k == 0.0 else 1]
        rows += [{"mesh": run.mesh, "k": run.k, "speed_fpm": run.speed_fpm, "lane": lane, "mass": run.mass,
                  "phi": phi + 0.1 * lane, "status": "scored"} for lane in range(run.lanes)]
    return rows


def test_loo_plans_reference_meshes_only_and_reports_each_fold(tmp_path, monkeypatch, capsys):
    planned = []
    monkeypatch.setattr(calibrate, "_evaluate", lambda runs, *a: planned.extend(runs) or fake_evaluate(runs, *a))
    assert calibrate.run_loo("builtin", None, tmp_path) == 0
    assert {r.mesh for r in planned} == set(PHI)  # the generated meshes of 'builtin' are not reference meshes
    assert {(r.k, r.speed_fpm) for r in planned} == {(0.0, 100.0), (100.0, 100.0), (0.0, 130.0), (100.0, 130.0)}
    mass = load_calibration().total_mass_kg
    assert all(not r.side and r.lanes == 3 and r.mass == mass for r in planned)
    report = json.loads((tmp_path / "loo.json").read_text())
    folds = {f["held_out"]: f for f in report["speeds"]["100"]["folds"]}
    assert set(folds) == set(PHI)
    assert (folds["seed0002"]["right"], folds["seed0002"]["total"]) == (1, 2)  # cut from the others: 5.1 .. 18.1
    assert (report["speeds"]["100"]["right"], report["speeds"]["100"]["total"]) == (5, 6)
    assert "held out seed0002" in capsys.readouterr().out and (tmp_path / "loo.md").exists()


def test_loo_refuses_a_set_without_two_reference_meshes(tmp_path):
    cmd = [sys.executable, "-c", "import sys; from woody_tools.cli import main; sys.exit(main(sys.argv[1:]))",
           "calibrate", "--loo", "--meshes", "generated:2:7", "--out", str(tmp_path)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "at least two reference" in done.stderr
