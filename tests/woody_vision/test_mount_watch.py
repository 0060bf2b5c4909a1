"""The vision nodes take the camera's mount from tf_static in place of their parameters (nodes built in process)."""

from __future__ import annotations

import dataclasses

import pytest

from woody_common import topics
from woody_sim.line_geometry import LineGeometry
from woody_sim.line_sim_node import _camera_info, static_transforms
from woody_vision.camera_model import edge_row

pytestmark = pytest.mark.ros
"""Builds nodes on a private domain."""

MOUNTED = dataclasses.replace(LineGeometry(lanes=3), top_height=0.6, top_center_x=-0.25)
"""A camera lower and further upstream than the parameters' defaults (0.75 m, 0.2 m)."""


@pytest.fixture
def grader(ros_domain):
    import rclpy

    from woody_vision.grader_node import Grader

    rclpy.init(args=["--ros-args", "-p", "use_side_view:=false"], domain_id=ros_domain)
    node = Grader()
    yield node
    node.destroy_node()
    rclpy.try_shutdown()


def test_the_grader_takes_height_and_edge_offset_from_tf_static(grader):
    info = _camera_info(MOUNTED.top_camera(), topics.TOP_FRAME)
    grader.mount_watch._on_tf_static(static_transforms(MOUNTED))
    grader.on_camera_info(info)
    assert grader.core.edge_row == pytest.approx(edge_row(tuple(info.k), 0.6, 0.25))
    assert grader.core.pixels_per_metre == pytest.approx(info.k[4] / 0.6)


def test_without_a_transform_to_the_cameras_frame_the_parameters_hold(grader):
    info = _camera_info(MOUNTED.top_camera(), "another_camera_optical_frame")
    grader.mount_watch._on_tf_static(static_transforms(MOUNTED))
    grader.on_camera_info(info)
    assert grader.core.edge_row == pytest.approx(edge_row(tuple(info.k), grader.camera_height, grader.edge_offset))
