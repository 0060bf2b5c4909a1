"""woody_common.line: the vision defaults are what the simulator's line geometry projects."""

import pytest

from woody_common.line import (
    CLASS_K,
    FPM_TO_MPS,
    LANE_PITCH_M,
    LANES,
    MAX_LANES,
    MAX_SPEED_MPS,
    PAPER_SPEEDS_FPM,
    REFERENCE_SPEED_FPM,
    REFERENCE_SPEED_MPS,
    ROLLER_RADIUS_M,
    SIDE_AXLE_PX,
    SIDE_ROLLER_RADIUS_PX,
    SPEED_RANGE_FPM,
    TOP_CAMERA_HEIGHT_M,
    TOP_EDGE_OFFSET_M,
    fpm_to_mps,
    mps_to_fpm,
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


def test_conversions_round_trip_through_one_factor():
    for fpm in (*SPEED_RANGE_FPM, *PAPER_SPEEDS_FPM, 117.5):
        assert mps_to_fpm(fpm_to_mps(fpm)) == pytest.approx(fpm, rel=1e-12)
    assert REFERENCE_SPEED_MPS == fpm_to_mps(REFERENCE_SPEED_FPM)
    assert MAX_SPEED_MPS == fpm_to_mps(SPEED_RANGE_FPM[1])  # one speed limit, in either unit
    assert REFERENCE_SPEED_FPM in PAPER_SPEEDS_FPM


def test_roller_lanes_and_classes_are_the_simulators():
    geometry = LineGeometry()
    assert geometry.roller_radius == ROLLER_RADIUS_M
    LineGeometry(lanes=MAX_LANES)
    with pytest.raises(ValueError, match=f"1..{MAX_LANES}"):
        LineGeometry(lanes=MAX_LANES + 1)
    assert CLASS_K == (0.0, 100.0)
