"""The experiment runner behind `woody sweep`: a run through a camera error model is scored and reproducible."""

from __future__ import annotations

import math

from woody_sim.meshes import load_mesh_set
from woody_tools.experiment import RunSpec, evaluate_run


def test_a_run_seen_through_a_noisy_camera_is_scored_and_reproducible():
    mesh = load_mesh_set("builtin")[0][0]
    spec = RunSpec(mesh.name, 0.0, 100.0, lanes=1, side=False, sensor="structured_light")
    noisy = evaluate_run(spec, mesh)
    assert evaluate_run(spec, mesh) == noisy
    ideal = evaluate_run(RunSpec(mesh.name, 0.0, 100.0, lanes=1, side=False), mesh)
    assert noisy[0]["status"] == ideal[0]["status"] == "scored", (noisy, ideal)
    assert math.isfinite(noisy[0]["phi"]) and noisy[0]["phi"] != ideal[0]["phi"]
