"""woody_common.line: the vision defaults are what the simulator's line geometry projects."""

import pytest

from woody_common.line import (
    FPM_TO_MPS,
    LANE_PITCH_M,
    LANES,
    SIDE_AXLE_PX,
    SIDE_ROLLER_RADIUS_PX,
    TOP_CAMERA_HEIGHT_M,
    TOP_EDGE_OFFSET_M,
    fpm_to_mps,
)
from woody_sim.line_geometry import LineGeometry


def test_side_camera_pixels_match_the_simulated_camera():
    geometry = LineGeometry()
    assert geometry.side_axle_pixel() == pytest.approx(SIDE_AXLE_PX, abs=0.5)
    assert geometry.side_roller_radius_px() == pytest.approx(SIDE_ROLLER_RADIUS_PX, abs=0.5)


def test_top_camera_and_lanes_are_the_geometry_defaults():
    geometry = LineGeometry()
    assert (geometry.top_height, -geometry.top_center_x) == (TOP_CAMERA_HEIGHT_M, TOP_EDGE_OFFSET_M)
    assert (geometry.lanes, geometry.lane_pitch) == (LANES, LANE_PITCH_M)


def test_100_fpm_is_0_508_mps():
    assert fpm_to_mps(100) == pytest.approx(0.508) == 100 * FPM_TO_MPS
