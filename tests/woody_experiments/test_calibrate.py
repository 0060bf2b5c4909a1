"""`woody calibrate`: the wiring of its steps (runs planned, folds reported, refusals), without the physics."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from woody_common.calibration import resolved_calibration
from woody_experiments import calibrate
from woody_sim.meshes import mesh_yaw
from woody_tools.cli import build_parser

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
    mass = resolved_calibration().total_mass_kg
    assert all(not r.side and r.lanes == 3 and r.mass == mass and r.yaw_deg == 0.0 for r in planned)
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


class _Planned(Exception):
    """Stops a calibration step once it has planned its runs."""


def test_yaw_sd_turns_every_run_of_every_step_and_is_recorded(tmp_path, monkeypatch):
    planned = []

    def capture(runs, *_):
        planned.append(list(runs))
        raise _Planned

    monkeypatch.setattr(calibrate, "_evaluate", capture)
    args = build_parser("calibrate").parse_args(
        ["calibrate", "--meshes", "generated:2:9", "--test-meshes", "generated:2:8", "--yaw-sd", "13",
         "--out", str(tmp_path), "--dry-run"])
    for step in ([], ["--skip-physics"]):
        args.skip_physics = bool(step)
        with pytest.raises(_Planned):
            calibrate.calibrate(args, None)
    monkeypatch.setattr(calibrate, "_evaluate", lambda runs, *a: planned.append(list(runs)) or fake_evaluate(runs, *a))
    assert calibrate.run_loo("builtin", None, tmp_path, yaw_sd=13.0) == 0
    fit, threshold, loo = planned
    assert {r.top for r in fit} == {False} and {r.side for r in threshold} == {False}
    for runs in planned:
        assert all(r.yaw_deg == mesh_yaw(r.mesh, 13.0) != 0.0 for r in runs)
    assert json.loads((tmp_path / "loo.json").read_text())["yaw_sd_deg"] == 13.0
    kept = {"fit_meshes": "generated-90000", "achieved_objective": 0.02, "date": "old"}
    provenance = calibrate._provenance(args, {}, kept)  # --skip-physics keeps the physics fit's record, not the rest
    assert provenance["yaw_sd_deg"] == 13.0 and provenance["fit_meshes"] == "generated-90000"
    assert provenance["achieved_objective"] == 0.02 and provenance["date"] != "old"


def test_the_threshold_and_line_cuts_are_fitted_through_the_top_camera_and_lanes_asked_for(tmp_path, monkeypatch):
    planned = []

    def capture(runs, *_):  # the threshold's calibration and held-out sets, then the line cuts' calibration set
        planned.append(list(runs))
        if len(planned) == 3:
            raise _Planned
        return [{"mesh": r.mesh, "k": r.k, "speed_fpm": r.speed_fpm, "lane": lane, "status": "scored",
                 "phi": 20.0 if r.k == 0.0 else 4.0} for r in runs for lane in range(r.lanes)]

    monkeypatch.setattr(calibrate, "_evaluate", capture)
    camera = "config/cameras/paper.yaml"
    args = build_parser("calibrate").parse_args(
        ["calibrate", "--meshes", "generated:2:9", "--test-meshes", "generated:2:8", "--skip-physics", "--dry-run",
         "--top-camera", camera, "--lanes", "3", "--out", str(tmp_path)])
    with pytest.raises(_Planned):
        calibrate.calibrate(args, None)
    threshold, held_out, line = planned
    assert {r.top_camera for runs in planned for r in runs} == {camera}
    assert {r.lanes for r in line} == {3} and {r.lanes for r in threshold + held_out} == {3}
    provenance = calibrate._provenance(args, {}, {})
    assert (provenance["top_camera"], provenance["lanes"]) == ("paper", 3)
