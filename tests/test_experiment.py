"""The experiment runner behind `woody sweep`: a run through a camera error model is scored and reproducible."""

from __future__ import annotations

import dataclasses
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


def test_the_colour_outline_keeps_a_stiff_fillet_woody_through_stereo_noise(monkeypatch):
    """seed0000 at k = 100 through the stereo preset: the depth-only outline frays past the Φ threshold (a woody
    fillet graded normal); the registered colour's outline, which the sweep uses for modelled cameras, does not."""
    from woody_common.calibration import load_calibration
    from woody_tools import experiment

    mesh = next(m for m in load_mesh_set("builtin")[0] if m.name == "seed0000")
    spec = RunSpec(mesh.name, 100.0, 100.0, lanes=1, side=False, sensor="stereo")
    assert experiment.REAL_CAMERA_SEGMENTATION.color_threshold > 0.0
    (with_colour,) = evaluate_run(spec, mesh)
    monkeypatch.setattr(experiment, "REAL_CAMERA_SEGMENTATION",
                        dataclasses.replace(experiment.REAL_CAMERA_SEGMENTATION, color_threshold=0.0))
    (depth_only,) = evaluate_run(spec, mesh)
    threshold = load_calibration().phi_threshold
    assert with_colour["phi"] < threshold < depth_only["phi"], (with_colour, depth_only)
