"""The image encodings a real RGB-D camera sends, converted to what the vision works on.

Depth drivers publish ``32FC1`` in metres or ``16UC1`` in millimetres (REP 118; another unit is a parameter);
both become float32 metres with NaN wherever the camera has no measurement
(NaN, ±inf, 0 or negative: stereo and structured-light cameras report a missing
pixel as 0), so a hole is never mistaken for something rising off the belt.
Colour comes as ``rgb8``, ``bgr8`` or ``mono8`` and becomes (H, W, 3) ``rgb8``.
Plain module (duck-typed on sensor_msgs/Image fields, no rclpy) so nodes and
tests share it; an encoding it cannot read raises FrameError with one line.
"""

from __future__ import annotations

import cv2
import numpy as np

from woody_common.line import DEPTH_UNIT_M
from woody_vision.frame_checks import FrameError, image_to_array

DEPTH_ENCODINGS = ("32FC1", "16UC1")
"""Depth encodings read: metres as float, millimetres as unsigned 16-bit."""
COLOR_ENCODINGS = ("rgb8", "bgr8", "mono8")
"""Colour encodings read; every one becomes rgb8."""
ASPECT_TOLERANCE = 0.02
"""Colour and depth images whose aspect ratios differ by more than this are not registered to each other."""


def depth_metres(msg, unit_m: float = DEPTH_UNIT_M) -> np.ndarray:
    """Depth image as float32 metres (a new array), NaN where the camera measured nothing; a 16UC1 step is
    ``unit_m``."""
    if msg.encoding == "16UC1":
        depth = image_to_array(msg, "16UC1").astype(np.float32) * np.float32(unit_m)
    elif msg.encoding == "32FC1":
        depth = np.array(image_to_array(msg, "32FC1"), dtype=np.float32)
    else:
        raise FrameError(f"depth encoding '{msg.encoding}' is not one of {', '.join(DEPTH_ENCODINGS)}; frame skipped")
    with np.errstate(invalid="ignore"):
        depth[~(np.isfinite(depth) & (depth > 0.0))] = np.nan
    return depth


def color_rgb(msg) -> np.ndarray:
    """Colour image as (H, W, 3) uint8 RGB (a view of the message data for rgb8, else a converted copy)."""
    if msg.encoding == "rgb8":
        return image_to_array(msg, "rgb8")
    if msg.encoding == "bgr8":
        return cv2.cvtColor(image_to_array(msg, "bgr8"), cv2.COLOR_BGR2RGB)
    if msg.encoding == "mono8":
        return cv2.cvtColor(image_to_array(msg, "mono8"), cv2.COLOR_GRAY2RGB)
    raise FrameError(f"colour encoding '{msg.encoding}' is not one of {', '.join(COLOR_ENCODINGS)}; frame skipped")


def match_size(rgb: np.ndarray, height: int, width: int) -> np.ndarray:
    """Colour resized to the depth image's size, for drawing depth-based contours on it.

    Only correct for a colour image registered to the depth image (same field of
    view, e.g. a driver's aligned-depth output at another resolution); a colour
    image with a different aspect ratio is refused, since pixels would not line up.
    """
    if rgb.shape[:2] == (height, width):
        return rgb
    if abs(rgb.shape[1] * height / (rgb.shape[0] * width) - 1.0) > ASPECT_TOLERANCE:
        raise FrameError(f"colour image {rgb.shape[1]}x{rgb.shape[0]} has another aspect ratio than the depth image "
                         f"{width}x{height}: not registered to it; publish depth aligned to colour")
    return cv2.resize(rgb, (width, height), interpolation=cv2.INTER_AREA)
