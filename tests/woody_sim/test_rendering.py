"""The cameras: metric depth, the roller edge where calibration says, side view of the watched lane only."""

from __future__ import annotations

import math

import numpy as np
import pytest

from woody_sim.line_geometry import LineGeometry, top_camera_preset
from woody_sim.rendering import (
    FRAMES_IN_FLIGHT,
    LineRenderer,
    RenderProcess,
    camera_info_fields,
    draped_poses,
    flat_poses,
    load_reference_visuals,
)


@pytest.fixture(scope="module")
def geometry():
    return LineGeometry()


@pytest.fixture(scope="module")
def reference():
    return load_reference_visuals(0, 40)


def test_empty_belt_depth_and_edge_row(geometry):
    renderer = LineRenderer(geometry, render_side=False)
    rgb, depth = renderer.render_top({})
    assert rgb.shape == (376, 672, 3) and rgb.dtype == np.uint8
    assert depth.shape == (376, 672) and depth.dtype == np.float32
    assert depth[188, 336] == pytest.approx(geometry.top_height, abs=0.001)
    edge = geometry.top_edge_row()
    column = depth[:, 336]
    assert np.all(column[: int(edge) - 1] < geometry.top_height + 0.01)  # belt up to the edge row
    assert np.all(column[int(edge) + 30:] > geometry.top_height + 0.3)  # the floor beyond the roller
    assert np.all(column[int(edge) + 1:int(edge) + 5] > geometry.top_height)  # the roller curving away


def test_flat_fillet_top_is_at_its_thickness(geometry, reference):
    visuals, offsets = reference
    renderer = LineRenderer(geometry, render_side=False)
    renderer.add_fillet(0, 1, visuals)
    _, depth = renderer.render_top({0: flat_poses(offsets, -0.35, geometry.lane_y(1))})
    thickness = max(float(np.asarray(v.vertices)[:, 2].max()) for v in visuals) - min(
        float(np.asarray(v.vertices)[:, 2].min()) for v in visuals)
    assert depth.min() == pytest.approx(geometry.top_height - thickness, abs=0.002)
    mask = depth < geometry.top_height - 0.003
    assert 2000 < mask.sum() < 8000  # a ~0.19 x 0.10 m fillet at ~490 px/m


def test_fillet_bent_over_the_roller_covers_less_of_the_top_view(geometry, reference):
    visuals, offsets = reference
    renderer = LineRenderer(geometry, render_side=False)
    renderer.add_fillet(0, 1, visuals)
    y = geometry.lane_y(1)
    _, flat = renderer.render_top({0: flat_poses(offsets, -0.35, y)})
    _, bent = renderer.render_top({0: draped_poses(offsets, 0.02, y, geometry.roller_radius)})
    background = renderer.render_top({})[1]

    def area(depth):
        return int((background - depth > 0.003).sum())

    assert area(bent) < 0.8 * area(flat)


def test_side_view_shows_roller_and_only_the_watched_lane(geometry, reference):
    visuals, offsets = reference
    renderer = LineRenderer(geometry, render_top=False)
    empty = renderer.render_side({})
    u, v = (int(round(c)) for c in geometry.side_axle_pixel())
    radius = geometry.side_roller_radius_px()
    outside = empty[v, u + int(radius) + 8].astype(int)
    for inside in (empty[v, u], empty[v, u + int(radius) - 5], empty[v + int(radius) - 5, u]):
        assert np.abs(inside.astype(int) - outside).sum() > 30  # the roller disc ends ~R px from the axle
    renderer.add_fillet(0, geometry.watched_lane, visuals)
    renderer.add_fillet(1, 0, visuals)
    # the side view spans 0.41 m centred on the axle (0.431 mm/px): a fillet centred 0.1 m before the edge
    watched = renderer.render_side({0: flat_poses(offsets, -0.1, geometry.lane_y(geometry.watched_lane)),
                                    1: flat_poses(offsets, -0.1, geometry.lane_y(0))})
    other_only = renderer.render_side({0: flat_poses(offsets, -2.0, geometry.lane_y(geometry.watched_lane)),
                                       1: flat_poses(offsets, -0.1, geometry.lane_y(0))})
    assert (np.abs(watched.astype(int) - empty.astype(int)).sum(axis=2) > 30).sum() > 1000
    assert np.array_equal(other_only, empty)


def test_render_process_matches_in_process_renderer(geometry, reference):
    visuals, offsets = reference
    poses = {3: draped_poses(offsets, 0.0, geometry.lane_y(1), geometry.roller_radius)}
    local = LineRenderer(geometry)
    local.add_fillet(3, 1, visuals)
    with RenderProcess(geometry) as remote:
        remote.add_fillet(3, 1, visuals)
        remote.submit(poses, want_top=True, want_side=True)
        frames = remote.collect()
    rgb, depth = local.render_top(poses)
    assert np.array_equal(frames.top_rgb, rgb) and np.array_equal(frames.top_depth, depth)
    assert np.array_equal(frames.side_rgb, local.render_side(poses))


def test_render_process_keeps_its_frames_in_flight_in_order(geometry, reference):
    visuals, offsets = reference
    near, far = ({3: flat_poses(offsets, x, geometry.lane_y(1))} for x in (-0.05, -0.3))
    local = LineRenderer(geometry)
    local.add_fillet(3, 1, visuals)
    assert FRAMES_IN_FLIGHT >= 2
    with RenderProcess(geometry) as remote:
        remote.add_fillet(3, 1, visuals)
        remote.submit(near, want_top=True, want_side=False)
        remote.submit(far, want_top=True, want_side=True)
        for _ in range(FRAMES_IN_FLIGHT - 2):
            remote.submit(near, want_top=True, want_side=False)
        assert not remote.can_submit
        with pytest.raises(RuntimeError, match="already in flight"):
            remote.submit(near)
        first, second, *rest = (remote.collect() for _ in range(FRAMES_IN_FLIGHT))
        assert not remote.busy
    assert all(np.array_equal(frame.top_depth, first.top_depth) for frame in rest)
    assert np.array_equal(first.top_depth, local.render_top(near)[1]) and first.side_rgb is None
    assert np.array_equal(second.top_depth, local.render_top(far)[1])
    assert np.array_equal(second.side_rgb, local.render_side(far))
    assert not np.array_equal(first.top_depth, second.top_depth)


def test_bad_input_is_refused(geometry, reference):
    visuals, offsets = reference
    renderer = LineRenderer(geometry)
    renderer.add_fillet(0, 1, visuals)
    with pytest.raises(ValueError, match="unknown fillet"):
        renderer.render_top({5: flat_poses(offsets, -0.3, 0.0)})
    with pytest.raises(ValueError):
        renderer.render_top({0: np.zeros((3, 7))})
    info = camera_info_fields(geometry.top_camera())
    assert info["width"] == 672 and info["K"][0] == pytest.approx(geometry.top_camera().fx)


def test_render_process_knows_when_the_side_view_is_empty(geometry, reference):
    visuals, offsets = reference
    lane = geometry.watched_lane
    with RenderProcess(geometry) as remote:
        remote.add_fillet(0, lane, visuals)
        remote.add_fillet(1, (lane + 1) % geometry.lanes, visuals)
        other_lane = {1: flat_poses(offsets, 0.0, geometry.lane_y((lane + 1) % geometry.lanes))}
        assert not remote.side_view_occupied(other_lane)
        assert not remote.side_view_occupied({0: flat_poses(offsets, -2.0, geometry.lane_y(lane)), **other_lane})
        assert remote.side_view_occupied({0: flat_poses(offsets, -0.1, geometry.lane_y(lane))})
        remote.remove_fillet(0)
        assert not remote.side_view_occupied(other_lane)


def test_paper_top_camera_preset_is_the_seed_systems_camera():
    paper = LineGeometry(**top_camera_preset("paper"))
    cam = paper.top_camera()
    # the seed's 960 x 696 with its 86.6 deg over the 696-px axis; flow runs down our rows, so 696 wide, 960 tall
    assert (cam.width, cam.height) == (696, 960)
    assert 2.0 * math.degrees(math.atan(cam.width / 2.0 / cam.fx)) == pytest.approx(86.6)
    assert cam.fx == cam.fy and paper.top_height == pytest.approx(0.33)
    across_m = cam.width / cam.fx * paper.top_height
    assert across_m == pytest.approx(2 * 0.33 * math.tan(math.radians(43.3)))
    assert across_m > paper.lanes * paper.lane_pitch  # all three lanes in view
    rgb, depth = LineRenderer(paper, render_side=False).render_top({})
    assert rgb.shape == (960, 696, 3) and depth.shape == (960, 696)
    assert depth[480, 348] == pytest.approx(0.33, abs=0.001)
    edge = int(paper.top_edge_row())
    assert depth[edge - 2, 348] < 0.34 and depth[edge + 60, 348] > 0.33 + 0.3  # belt, then the floor
    assert top_camera_preset("default") == {} and LineGeometry(**top_camera_preset("default")) == LineGeometry()
    with pytest.raises(ValueError, match="known: default, paper"):
        top_camera_preset("wide")
