"""Depth and colour encodings a real camera sends, converted to metres and rgb8."""

from __future__ import annotations

import numpy as np
import pytest
from test_frame_checks import image_msg

from woody_vision.frame_checks import FrameError
from woody_vision.image_encodings import color_rgb, depth_metres, match_size
from woody_vision.segmentation import BackgroundModel, segment_depth
from woody_vision.synthetic import TopFillet, TopScene

RGB = np.arange(4 * 5 * 3, dtype=np.uint8).reshape(4, 5, 3)


def test_32fc1_depth_is_metres_with_nan_for_every_missing_return():
    depth = np.array([[0.75, 0.0, np.nan], [np.inf, -np.inf, -0.2]], np.float32)
    out = depth_metres(image_msg(depth, "32FC1"))
    assert out.dtype == np.float32 and out[0, 0] == pytest.approx(0.75)
    assert np.isnan(out.reshape(-1)[1:]).all()


def test_16uc1_depth_is_millimetres_with_zero_as_missing():
    mm = np.array([[750, 0], [1, 65535]], np.uint16)
    out = depth_metres(image_msg(mm, "16UC1", pad=4))
    assert out[0, 0] == pytest.approx(0.75) and out[1, 0] == pytest.approx(0.001) and out[1, 1] == pytest.approx(65.535)
    assert np.isnan(out[0, 1])
    swapped = mm.byteswap()
    assert np.allclose(depth_metres(image_msg(swapped, "16UC1", bigendian=True)), out, equal_nan=True)
    tenths = depth_metres(image_msg(mm, "16UC1"), unit_m=0.0001)  # a driver counting in 0.1 mm
    assert tenths[0, 0] == pytest.approx(0.075) and np.isnan(tenths[0, 1])


def test_depth_in_another_encoding_is_refused_with_one_line():
    with pytest.raises(FrameError, match="16UC1") as info:
        depth_metres(image_msg(np.zeros((2, 2), np.uint8), "mono8"))
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("encoding, array", [("rgb8", RGB), ("bgr8", RGB[:, :, ::-1]),
                                             ("mono8", RGB[:, :, 1])])
def test_every_colour_encoding_becomes_rgb8(encoding, array):
    out = color_rgb(image_msg(array, encoding, pad=3))
    assert out.shape == (4, 5, 3) and out.dtype == np.uint8
    if encoding == "mono8":
        assert (out == RGB[:, :, 1:2]).all()
    else:
        assert np.array_equal(out, RGB)


def test_colour_in_another_encoding_is_refused_with_one_line():
    with pytest.raises(FrameError, match="rgb8, bgr8, mono8"):
        color_rgb(image_msg(np.zeros((2, 2), np.float32), "32FC1"))


def test_registered_colour_of_another_size_is_resized_and_unregistered_colour_refused():
    colour = np.zeros((720, 1280, 3), np.uint8)
    assert match_size(colour, 376, 672).shape == (376, 672, 3)
    assert match_size(RGB, 4, 5) is RGB
    with pytest.raises(FrameError, match="aspect ratio"):
        match_size(np.zeros((480, 640, 3), np.uint8), 376, 672)


def test_zero_holes_and_all_zero_frames_are_never_fillets():
    scene = TopScene([TopFillet(lead_m=-0.05, across_m=0.0)])
    background = depth_metres(image_msg(scene.background_depth(), "32FC1"))
    mm = np.round(scene.render(0.0)[1] * 1000.0).astype(np.uint16)
    assert len(segment_depth(depth_metres(image_msg(mm, "16UC1")), background)) == 1
    holed = mm.copy()
    holed[20:60, 20:60] = 0  # a 40 x 40 px hole of missing returns on the belt
    assert len(segment_depth(depth_metres(image_msg(holed, "16UC1")), background)) == 1
    zero = np.zeros_like(mm)
    assert segment_depth(depth_metres(image_msg(zero, "16UC1")), background) == []
    model = BackgroundModel(2)  # a camera that starts with all-zero frames learns nothing from them
    model.add(depth_metres(image_msg(zero, "16UC1")))
    model.add(depth_metres(image_msg(zero, "16UC1")))
    assert segment_depth(depth_metres(image_msg(mm, "16UC1")), model.depth) == []
