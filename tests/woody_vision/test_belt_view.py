"""BeltView: a camera mounted off straight down, turned, beside the belt's middle and with a distorting lens
seen as its belt camera (straight down, centred), on frames the twin's renderer makes for that camera."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from woody_sim.camera_description import load_camera
from woody_sim.line_geometry import LineGeometry
from woody_sim.rendering import LineRenderer, camera_info_fields, draped_poses, flat_poses, load_reference_visuals
from woody_vision.belt_view import BeltView, CameraModel, straight_down_pose
from woody_vision.static_frames import STRAIGHT_DOWN, Pose

CAMERAS = Path(__file__).resolve().parents[2] / "config" / "cameras"
VISUALS, OFFSETS = load_reference_visuals()


def camera_model(geometry: LineGeometry) -> CameraModel:
    return CameraModel.of(camera_info_fields(geometry.top_camera()))


def pose(geometry: LineGeometry) -> Pose:
    camera = geometry.top_camera()
    return Pose(np.array(camera.position), np.array(camera.rotation))


def belt_camera(geometry: LineGeometry) -> LineGeometry:
    """The geometry of the camera's belt camera: its intrinsics, height and place along the flow, centred, straight
    down, no distortion."""
    c = geometry.top_camera()
    return LineGeometry(top_width=c.width, top_height_px=c.height, top_intrinsics=(c.fx, c.fy, c.cx, c.cy),
                        top_height=c.position[2], top_center_x=c.position[0])


def render(geometry: LineGeometry, poses: np.ndarray | None) -> np.ndarray:
    renderer = LineRenderer(geometry, render_side=False)
    renderer.add_fillet(1, 1, VISUALS)
    return renderer.render_top({} if poses is None else {1: poses})[1]


def fillet_mask(geometry: LineGeometry, poses: np.ndarray, view: BeltView | None = None) -> np.ndarray:
    depth, background = render(geometry, poses), render(geometry, None)
    if view is not None:
        depth, background = view.depth(depth), view.depth(background)
    return (background - depth) > 0.002


def test_a_straight_down_centred_camera_without_distortion_passes_its_frames_unchanged():
    geometry = LineGeometry()
    view = BeltView(camera_model(geometry), pose(geometry))
    depth = render(geometry, flat_poses(OFFSETS, -0.25, 0.0))
    assert view.identity and view.depth(depth) is depth and view.height_m == geometry.top_height


@pytest.mark.parametrize("name", ["realsense-d435", "orbbec-femto"])
def test_a_plant_cameras_frames_show_the_belt_and_a_fillet_as_its_belt_camera_does(name):
    real = LineGeometry(**load_camera(CAMERAS / f"{name}.yaml").geometry_overrides())
    ideal = belt_camera(real)
    view = BeltView(camera_model(real), pose(real))
    assert not view.identity
    belt, seen = render(ideal, None), view.depth(render(real, None))
    on_belt = np.isfinite(belt) & (belt <= real.top_height + 1e-3) & np.isfinite(seen)
    assert np.mean(np.abs(seen - belt)[on_belt] < 1e-3) > 0.99  # the belt plane at its depth, to a mm
    flat = flat_poses(OFFSETS, -0.25, 0.0)
    lying, seen_lying = fillet_mask(ideal, flat), fillet_mask(real, flat, view)
    assert (lying & seen_lying).sum() / (lying | seen_lying).sum() > 0.97
    hanging = draped_poses(OFFSETS, 0.03, 0.0, real.roller_radius)  # over the edge: height x tilt of parallax
    bent, seen_bent = fillet_mask(ideal, hanging), fillet_mask(real, hanging, view)
    assert (bent & seen_bent).sum() / (bent | seen_bent).sum() > 0.9


def test_a_lens_or_a_mount_the_belt_view_cannot_take_is_refused_in_one_line():
    camera = camera_model(LineGeometry())
    fisheye = CameraModel(camera.width, camera.height, camera.k, (0.1, 0.01, 0.0, 0.0), "equidistant")
    with pytest.raises(ValueError, match="distortion model 'equidistant' is not one of"):
        BeltView(fisheye, straight_down_pose(0.75))
    leaning = Pose(np.array([0.0, 0.0, 0.75]), Rotation.from_euler("y", 25, degrees=True).as_matrix() @ STRAIGHT_DOWN)
    with pytest.raises(ValueError, match="looks 25.0 deg from straight down"):
        BeltView(camera, leaning)
