"""woody_vision.camera_model.belt_outline: the perspective of the drop below the belt taken out of an outline."""

from __future__ import annotations

import numpy as np

from woody_vision.camera_model import belt_outline

K = (500.0, 0.0, 320.0, 0.0, 500.0, 180.0, 0.0, 0.0, 1.0)
HEIGHT = 0.75


def test_a_point_on_the_belt_stays_and_one_below_it_moves_out_from_the_optical_axis():
    depth = np.full((360, 640), HEIGHT, np.float32)
    depth[100, 600] = HEIGHT + 0.05  # hanging 5 cm below the belt, off to the right
    depth[100, 40] = HEIGHT + 0.05  # the same on the left: the same shift, mirrored
    depth[180, 320] = HEIGHT + 0.05  # on the optical axis: no shift at all
    out = belt_outline(np.array([[500, 50], [600, 100], [40, 100], [320, 180]]), depth, K, HEIGHT)
    assert out.dtype == np.int32 and out.tolist()[0] == [500, 50] and out.tolist()[3] == [320, 180]
    # the camera saw the hanging point at (600, 100); on the belt plane it lies (z / H) as far from the axis
    assert out.tolist()[1] == [round(320 + 280 * 0.80 / 0.75), round(180 - 80 * 0.80 / 0.75)]
    assert out[2, 0] - 320 == -(out[1, 0] - 320) and out[2, 1] == out[1, 1]


def test_one_bend_seen_from_either_side_of_the_axis_gives_one_outline():
    """The same hanging tip, once left and once right of the optical axis, comes out mirror-symmetric."""
    depth = np.full((360, 640), HEIGHT, np.float32)
    tip = np.array([[250, 200], [270, 200], [270, 230], [250, 230]])
    mirrored = np.column_stack([640 - tip[:, 0], tip[:, 1]])
    for points in (tip, mirrored):
        depth[points[:, 1], points[:, 0]] = HEIGHT + 0.08
    left, right = belt_outline(tip, depth, K, HEIGHT), belt_outline(mirrored, depth, K, HEIGHT)
    assert np.array_equal(640 - left[:, 0], right[:, 0]) and np.array_equal(left[:, 1], right[:, 1])


def test_a_point_without_depth_keeps_its_place():
    depth = np.full((360, 640), np.nan, np.float32)
    depth[0, 0] = 0.0
    points = np.array([[600, 100], [0, 0], [700, 400]])  # the last one outside the image: clipped to read depth
    assert belt_outline(points, depth, K, HEIGHT).tolist() == points.tolist()


def test_a_point_above_the_belt_keeps_its_place():
    """A fillet's top seen from aside is where the ray grazes its side: moving it in by its height would narrow
    the far side of a fillet in an outer lane."""
    depth = np.full((360, 640), HEIGHT - 0.03, np.float32)
    points = np.array([[600, 100], [40, 300], [320, 180]])
    assert belt_outline(points, depth, K, HEIGHT).tolist() == points.tolist()
