"""The top camera's mount from static transforms: line_sim's own frames, a driver's chain, refusals."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from woody_common import topics
from woody_common.line import MAX_CAMERA_TILT_DEG
from woody_sim.line_geometry import LineGeometry
from woody_sim.line_sim_node import static_transforms
from woody_vision.static_frames import STRAIGHT_DOWN, StaticFrames, camera_mount, mount_problem


def test_line_sims_frames_give_its_camera_height_and_edge_offset():
    geometry = LineGeometry(lanes=6)
    frames = StaticFrames()
    frames.add_message(static_transforms(geometry))
    mount = camera_mount(frames.lookup(topics.WORLD_FRAME, topics.TOP_FRAME))
    assert mount.height_m == pytest.approx(geometry.top_height)
    assert mount.edge_offset_m == pytest.approx(-geometry.top_center_x)
    assert mount.tilt_deg == pytest.approx(0.0, abs=1e-6) and mount_problem(mount) == ""


def test_a_chain_through_a_drivers_frames_composes():
    """A static_transform_publisher places the camera's body in the belt frame, the driver its optical frame in the
    body: the mount is that of the composed transform."""
    body = Rotation.from_euler("zyx", [90, 90, 0], degrees=True).as_matrix()  # body x down, y downstream
    optical_in_body = body.T @ STRAIGHT_DOWN
    frames = StaticFrames()
    frames.add("world", "camera_link", (-0.15, 0.02, 0.6), Rotation.from_matrix(body).as_quat())
    frames.add("camera_link", "camera_color_optical_frame", (0.01, 0.015, 0.0),
               Rotation.from_matrix(optical_in_body).as_quat())
    pose = frames.lookup("world", "/camera_color_optical_frame")
    assert np.allclose(pose.rotation, STRAIGHT_DOWN, atol=1e-9)
    origin = np.array([-0.15, 0.02, 0.6]) + body @ np.array([0.01, 0.015, 0.0])
    mount = camera_mount(pose)
    assert (mount.height_m, mount.edge_offset_m) == pytest.approx((origin[2], -origin[0]))
    assert frames.lookup("world", "another_camera_frame") is None


def test_a_camera_leaning_past_the_limit_or_below_the_belt_is_refused_in_one_line():
    """A few degrees of tilt, roll or any yaw is a mount the belt view takes; a camera leaning further than
    MAX_CAMERA_TILT_DEG, or one below the belt, is not."""
    frames = StaticFrames()
    for tilt, ok in ((5.0, True), (MAX_CAMERA_TILT_DEG + 1.0, False)):
        leaning = Rotation.from_euler("zyx", [30.0, tilt, 0.0], degrees=True).as_matrix() @ STRAIGHT_DOWN
        frames.add("world", "cam", (0.0, 0.0, 0.7), Rotation.from_matrix(leaning).as_quat())
        mount = camera_mount(frames.lookup("world", "cam"))
        assert math.isclose(mount.tilt_deg, tilt, abs_tol=1e-6)
        assert (mount_problem(mount) == "") == ok
        assert ok or f"looks {tilt:.1f} deg from straight down" in mount_problem(mount)
    frames.add("world", "cam", (0.0, 0.0, -0.1), Rotation.from_matrix(STRAIGHT_DOWN).as_quat())
    assert "not above it" in mount_problem(camera_mount(frames.lookup("world", "cam")))
