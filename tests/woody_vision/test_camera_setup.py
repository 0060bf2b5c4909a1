"""Camera setup from a recording: the mount, the flow, the roller edge and the lanes found again in frames the
twin renders for a described camera; what a recording cannot tell is refused in one line."""

from __future__ import annotations

from pathlib import Path

import pytest
import trimesh

from woody_sim.camera_description import load_camera
from woody_sim.line_geometry import LineGeometry
from woody_sim.rendering import LineRenderer, camera_info_fields, flat_poses, visuals_from_mesh
from woody_vision.belt_view import CameraModel
from woody_vision.camera_setup import SetupError, find_setup

CAMERAS = Path(__file__).resolve().parents[2] / "config" / "cameras"
FPS = 30.0
SPEED = 0.5
BODY = trimesh.creation.icosphere(subdivisions=3).apply_scale((0.095, 0.02, 0.045))
"""A fillet-sized ellipsoid (mesh axes: x along, y up): symmetric, so its centroid rides on its lane's centre."""
VISUALS, OFFSETS = visuals_from_mesh(BODY.vertices, BODY.faces, 40)


def recording(geometry: LineGeometry, empty: int = 6, moving: int = 30, end_x: float = -0.02):
    """(camera model, frames): ``empty`` frames of the empty belt, then one fillet per lane riding flat at SPEED
    until its centre is at ``end_x``."""
    renderer = LineRenderer(geometry, render_side=False)
    for lane in range(geometry.lanes):
        renderer.add_fillet(lane, lane, VISUALS)
    frames = []
    for i in range(empty + moving):
        x = end_x - SPEED * (empty + moving - 1 - i) / FPS
        poses = {} if i < empty else {lane: flat_poses(OFFSETS, x, geometry.lane_y(lane))
                                      for lane in range(geometry.lanes)}
        frames.append((i / FPS, renderer.render_top(poses)[1]))
    return CameraModel.of(camera_info_fields(geometry.top_camera())), frames


@pytest.mark.parametrize("name", ["realsense-d435", "orbbec-femto"])
def test_the_mount_flow_edge_and_lanes_are_found_again(name):
    described = load_camera(CAMERAS / f"{name}.yaml")
    found = find_setup(*recording(LineGeometry(**described.geometry_overrides())))
    tilt, roll, yaw = found.mount_deg()
    assert found.height_m == pytest.approx(described.height_m, abs=0.003)
    assert (tilt, roll, yaw) == pytest.approx((described.tilt_deg, described.roll_deg, described.yaw_deg), abs=0.3)
    assert found.pose.translation[:2] == pytest.approx((described.along_m, described.across_m), abs=0.005)
    assert found.edge_offset_m == pytest.approx(-described.along_m, abs=0.005)
    # a dome shows the camera more of its near side the further it is from the axis, which slows its centroid by
    # a few per cent; a real fillet's flat top much less (1.5 % on a live recording, docs/real-camera.md)
    assert found.speed_mps == pytest.approx(SPEED, rel=0.04)
    assert found.lanes == 3 and found.lane_pitch_m == pytest.approx(0.16, abs=0.005)


def test_what_a_recording_cannot_tell_is_refused_in_one_line():
    geometry = LineGeometry(**load_camera(CAMERAS / "realsense-d435.yaml").geometry_overrides())
    with pytest.raises(SetupError, match="no empty-belt frames at the start"):
        find_setup(*recording(geometry, empty=1))
    model, frames = recording(geometry, moving=0)
    with pytest.raises(SetupError, match="no fillet moving on the belt"):
        find_setup(model, frames)
    with pytest.raises(SetupError, match="no fillet crossing the roller edge"):
        find_setup(*recording(geometry, end_x=-0.2))
    upstream = LineGeometry(**{**load_camera(CAMERAS / "realsense-d435.yaml").geometry_overrides(),
                               "top_center_x": -0.7})
    with pytest.raises(SetupError, match="the roller edge is not in view"):
        find_setup(*recording(upstream, end_x=-0.5))
