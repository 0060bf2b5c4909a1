"""The experiment runner behind `woody sweep`: a run through a camera error model is scored and reproducible."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from woody_common.line import fpm_to_mps
from woody_experiments.experiment import RunSpec, evaluate_run
from woody_sim.line_conditions import place_mesh
from woody_sim.meshes import load_mesh_set


def test_a_run_seen_through_a_noisy_camera_is_scored_and_reproducible():
    mesh = load_mesh_set("builtin")[0][0]
    spec = RunSpec(mesh.name, 0.0, 100.0, lanes=1, side=False, sensor="structured_light")
    noisy = evaluate_run(spec, mesh)
    assert evaluate_run(spec, mesh) == noisy
    ideal = evaluate_run(RunSpec(mesh.name, 0.0, 100.0, lanes=1, side=False), mesh)
    assert noisy[0]["status"] == ideal[0]["status"] == "scored", (noisy, ideal)
    assert math.isfinite(noisy[0]["phi"]) and noisy[0]["phi"] != ideal[0]["phi"]


def test_a_run_through_a_plant_camera_is_scored_in_its_belt_view_as_through_the_default_camera():
    """An Orbbec-class camera (tilted, rolled, turned, off the middle, barrel distortion): the sweep's vision
    resamples its frames into the belt view, as the segmenter does, and the line score stays close."""
    mesh = load_mesh_set("builtin")[0][0]
    orbbec = str(Path(__file__).resolve().parents[2] / "config" / "cameras" / "orbbec-femto.yaml")
    for k in (0.0, 100.0):
        plant = evaluate_run(RunSpec(mesh.name, k, 100.0, lanes=1, side=False, top_camera=orbbec), mesh)[0]
        ideal = evaluate_run(RunSpec(mesh.name, k, 100.0, lanes=1, side=False), mesh)[0]
        assert plant["status"] == ideal["status"] == "scored", (plant, ideal)
        assert plant["line_phi"] == pytest.approx(ideal["line_phi"], rel=0.3, abs=1.0)


def test_a_side_view_only_run_measures_the_watched_lane_without_a_top_camera():
    """`woody calibrate` fits the physics on side-view-only runs (top=False): no top camera is built."""
    mesh = load_mesh_set("builtin")[0][0]
    rows = evaluate_run(RunSpec(mesh.name, 100.0, 100.0, lanes=1, top=False), mesh)
    assert len(rows) == 1 and math.isfinite(rows[0]["nmdm"]) and rows[0]["status"] == ""


def test_a_fillet_lying_turned_on_the_belt_is_simulated_turned_and_still_scored(monkeypatch):
    from woody_experiments import experiment

    placed = []
    monkeypatch.setattr(experiment, "place_mesh", lambda mesh, p: placed.append(p) or place_mesh(mesh, p))
    mesh = load_mesh_set("builtin")[0][0]
    straight = evaluate_run(RunSpec(mesh.name, 0.0, 100.0, lanes=1, side=False), mesh)
    assert placed[-1].keeps_mesh
    (row,) = evaluate_run(RunSpec(mesh.name, 0.0, 100.0, lanes=1, side=False, yaw_deg=15.0), mesh)
    assert placed[-1].yaw_deg == 15.0 and row["status"] == "scored" and row["phi"] != straight[0]["phi"]
    assert row["yaw_deg"] == 15.0 and row["leading_end"] == "narrow"


def test_a_condition_lays_the_fillet_as_drawn_with_the_mass_following_its_size():
    mesh = load_mesh_set("builtin")[0][0]
    spec = RunSpec(mesh.name, 0.0, 130.0, lanes=1, side=False, mass=20.0, condition="messy")
    (row,) = evaluate_run(spec, mesh)
    placement = spec.placement
    assert placement == RunSpec(mesh.name, 100.0, 130.0, condition="messy").placement  # paired across k
    assert row["scale"] == placement.scale and row["mass"] == pytest.approx(20.0 * placement.scale ** 3)
    assert row["leading_end"] == ("blunt" if placement.blunt_first else "narrow")
    assert row["status"] == "scored" and row["speed_mps"] == pytest.approx(fpm_to_mps(130.0), rel=0.03)
    (blunt,) = evaluate_run(RunSpec(mesh.name, 0.0, 100.0, lanes=1, side=False, condition="blunt"), mesh)
    assert blunt["blunt_first"] == 1 and blunt["leading_end"] == "blunt" and math.isfinite(blunt["line_phi"])


def test_the_colour_outline_keeps_a_stiff_fillet_woody_through_stereo_noise(monkeypatch):
    """seed0000 at k = 100 through the stereo preset: the depth-only outline frays (beyond the fillet's own outline,
    its frames are rejected and the fillet unscored; scored, it lies past the Φ threshold); the registered colour's
    outline, which the sweep uses for modelled cameras, keeps it woody."""
    from woody_common.calibration import resolved_calibration
    from woody_experiments import experiment

    mesh = next(m for m in load_mesh_set("builtin")[0] if m.name == "seed0000")
    spec = RunSpec(mesh.name, 100.0, 100.0, lanes=1, side=False, sensor="stereo")
    assert experiment.REAL_CAMERA_SEGMENTATION.color_threshold > 0.0
    (with_colour,) = evaluate_run(spec, mesh)
    monkeypatch.setattr(experiment, "REAL_CAMERA_SEGMENTATION",
                        dataclasses.replace(experiment.REAL_CAMERA_SEGMENTATION, color_threshold=0.0))
    (depth_only,) = evaluate_run(spec, mesh)
    threshold = resolved_calibration().phi_threshold
    assert with_colour["status"] == "scored" and with_colour["phi"] < threshold, with_colour
    assert depth_only["status"] == "unscored" or depth_only["phi"] > threshold, depth_only


def test_a_three_lane_run_simulates_one_chain_and_scores_every_lane_from_its_own_perspective(monkeypatch):
    from woody_sim.line_world import LineWorld

    spawned = []
    spawn = LineWorld.spawn
    monkeypatch.setattr(LineWorld, "spawn", lambda self, *a, **kw: spawned.append(kw["lane"]) or spawn(self, *a, **kw))
    mesh = load_mesh_set("builtin")[0][0]
    rows = evaluate_run(RunSpec(mesh.name, 0.0, 100.0, side=False), mesh)
    assert spawned == [1]  # the watched (centre) lane
    assert [r["status"] for r in rows] == ["scored"] * 3, rows
    phis = [r["phi"] for r in rows]
    assert len(set(phis)) == 3 and max(phis) < 1.3 * min(phis), phis  # same bend, three perspectives


def test_lane_copies_are_the_chain_shifted_across_the_belt_and_leave_with_it():
    import numpy as np

    from woody_experiments.experiment import _LaneCopies
    from woody_sim.line_geometry import LineGeometry
    from woody_sim.line_world import LineWorld
    from woody_sim.rendering import LineRenderer

    geometry = LineGeometry(lanes=3)
    renderer = LineRenderer(geometry, render_top=True, render_side=False)
    mesh = load_mesh_set("builtin")[0][0]
    with LineWorld(geometry) as world:
        fid = world.spawn(mesh, k=0.0, lane=geometry.watched_lane, mass=20.0, speed_mps=0.5)
        lanes = _LaneCopies(world, renderer, geometry, fid)
        for _ in range(50):
            world.step()
        chain = world.segment_poses()[fid]
        poses = lanes.poses()
        assert set(poses) == set(renderer.fillet_ids) and len(poses) == 3
        for lane, render_id in enumerate((_LaneCopies.COPY_ID_BASE, fid, _LaneCopies.COPY_ID_BASE + 2)):
            shifted = chain.copy()
            shifted[:, 1] += geometry.lane_y(lane) - geometry.lane_y(1)
            np.testing.assert_array_equal(poses[render_id], shifted)
        lanes.remove()
        assert renderer.fillet_ids == [] and lanes.poses() == {}


def test_a_run_can_change_the_belt_speed_and_lay_its_lanes_at_another_pitch():
    mesh = load_mesh_set("builtin")[0][0]
    (steady,) = evaluate_run(RunSpec(mesh.name, 0.0, 100.0, lanes=1, side=False), mesh)
    (faster,) = evaluate_run(RunSpec(mesh.name, 0.0, 100.0, lanes=1, side=False, speed_change_fpm=130.0,
                                     speed_change_at_s=0.0), mesh)
    assert faster["status"] == "scored" and faster["speed_mps"] == pytest.approx(fpm_to_mps(130.0), rel=0.03)
    assert steady["speed_mps"] == pytest.approx(fpm_to_mps(100.0), rel=0.03)
    narrow = evaluate_run(RunSpec(mesh.name, 0.0, 100.0, lanes=3, side=False, lane_pitch_m=0.13), mesh)
    assert [r["status"] for r in narrow] == ["scored"] * 3
