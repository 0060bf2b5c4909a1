"""Camera description files: every file under config/cameras loads and places its camera as it says; a bad file
is refused in one line; the twin's camera_info carries the lens."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from woody_sim.camera_description import CameraDescription, load_camera
from woody_sim.line_geometry import LineGeometry, top_camera_preset
from woody_sim.rendering import LineRenderer, camera_info_fields

CAMERAS = Path(__file__).resolve().parents[2] / "config" / "cameras"


@pytest.mark.parametrize("path", sorted(CAMERAS.glob("*.yaml")), ids=lambda p: p.stem)
def test_every_camera_file_places_its_camera_as_it_says(path):
    described = load_camera(path)
    camera = LineGeometry(**top_camera_preset(str(path))).top_camera()
    assert (camera.width, camera.height, camera.fx, camera.fy) == (described.width, described.height, described.fx,
                                                                   described.fy)
    assert camera.position == pytest.approx((described.along_m, described.across_m, described.height_m))
    axes = np.array(camera.rotation)
    optical_z, rows = axes[:, 2], axes[:, 1]
    assert math.degrees(math.asin(optical_z[0])) == pytest.approx(described.tilt_deg, abs=0.05)  # downstream
    assert math.degrees(math.atan2(rows[1], rows[0])) == pytest.approx(described.yaw_deg, abs=0.05)
    assert math.degrees(math.atan2(optical_z[1], -optical_z[2])) == pytest.approx(described.roll_deg, abs=0.2)


@pytest.mark.parametrize("preset", ["default", "paper"])
def test_the_default_and_paper_files_are_the_presets_cameras(preset):
    from_file = LineGeometry(**top_camera_preset(str(CAMERAS / f"{preset}.yaml"))).top_camera()
    from_preset = LineGeometry(**top_camera_preset(preset)).top_camera()
    for name in ("width", "height", "fx", "fy", "cx", "cy", "position", "rotation"):
        assert np.allclose(getattr(from_file, name), getattr(from_preset, name), atol=1e-3), name


@pytest.mark.parametrize("text, message", [
    ("width: 640\nheight: 480\n", "missing key intrinsics"),
    ("width: 640\nheight: 480\nintrinsics: {fx: 500, fy: 500, cx: 320, cy: 240}\nzoom: 2\n", "unknown keys zoom"),
    ("width: 640\nheight: 480\nintrinsics: {fx: 500, fy: 500, cx: 320, cy: 240}\nmount: {tilt_deg: 30}\n",
     "lean at most 20 deg"),
    ("width: 640\nheight: 480\nintrinsics: {fx: 500, fy: 500, cx: 320, cy: 240}\nsensor: lidar\n",
     "sensor must be one of"),
    ("[1, 2", "cannot read it"),
])
def test_a_bad_camera_file_is_refused_in_one_line_naming_it(tmp_path, text, message):
    path = tmp_path / "mine.yaml"
    path.write_text(text)
    with pytest.raises(ValueError, match=message) as refused:
        load_camera(path)
    assert str(path) in str(refused.value) and "\n" not in str(refused.value)


def test_camera_info_carries_the_lens_and_the_render_is_distorted():
    orbbec = LineGeometry(**top_camera_preset(str(CAMERAS / "orbbec-femto.yaml")))
    fields = camera_info_fields(orbbec.top_camera())
    assert fields["distortion_model"] == "rational_polynomial" and fields["d"] == list(load_camera(
        CAMERAS / "orbbec-femto.yaml").distortion)
    plain = LineGeometry(**{**top_camera_preset(str(CAMERAS / "orbbec-femto.yaml")), "top_distortion": ()})
    assert camera_info_fields(plain.top_camera())["d"] == [0.0] * 5
    distorted = LineRenderer(orbbec, render_side=False).render_top({})[1]
    ideal = LineRenderer(plain, render_side=False).render_top({})[1]
    assert distorted.shape == ideal.shape == (orbbec.top_height_px, orbbec.top_width)
    assert np.mean(np.isclose(distorted, ideal, equal_nan=True)) < 0.9  # the belt's edges bend in the image


def test_a_description_checks_its_values():
    with pytest.raises(ValueError, match="principal point"):
        CameraDescription(width=64, height=48, fx=50.0, fy=50.0, cx=100.0, cy=24.0)
