"""Deterministic messages of the project's types, message i of each topic, for recorder/replay tests.

Shared by the publishing helper (`publish_known.py`) and the tests that check
what a bag holds; plus `same()`, a field-by-field comparison of an rclpy message
with what another decoder (rosbags, mcap_ros2) made of the same bytes.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

from builtin_interfaces.msg import Time
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from msg_samples import samples  # noqa: E402

RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)

# topic: (type, qos)
TOPICS = {
    "/clock": (Clock, RELIABLE),
    "/top_camera/color/image_raw": (Image, RELIABLE),
    "/top_camera/color/camera_info": (CameraInfo, RELIABLE),
    "/vision/tracks": (type(samples()["FilletTrackArray"]), RELIABLE),
    "/grading/verdicts": (type(samples()["FilletVerdict"]), RELIABLE),
    "/reject_gate/commands": (type(samples()["GateCommand"]), RELIABLE),
    "/line/ground_truth": (type(samples()["FilletSpawn"]), LATCHED),
}


def stamp(i: int) -> Time:
    return Time(sec=100 + i // 10, nanosec=(i % 10) * 100_000_000)


def known(topic: str, i: int, small_images: bool = False):
    """Message ``i`` of ``topic``."""
    if topic == "/clock":
        return Clock(clock=stamp(i))
    if topic == "/top_camera/color/image_raw":
        width, height = (64, 48) if small_images else (672, 376)
        row = bytes((x + i) % 256 for x in range(width * 3))
        msg = Image(height=height, width=width, encoding="rgb8", step=width * 3, data=row * height)
        msg.header.stamp, msg.header.frame_id = stamp(i), "top_camera_color_optical_frame"
        return msg
    if topic == "/top_camera/color/camera_info":
        msg = CameraInfo(width=672, height=376, distortion_model="plumb_bob", d=[0.0] * 5,
                         k=[500.0 + i, 0.0, 336.0, 0.0, 500.0, 188.0, 0.0, 0.0, 1.0])
        msg.header.stamp, msg.header.frame_id = stamp(i), "top_camera_color_optical_frame"
        return msg
    sample = {"/vision/tracks": "FilletTrackArray", "/grading/verdicts": "FilletVerdict",
              "/reject_gate/commands": "GateCommand", "/line/ground_truth": "FilletSpawn"}[topic]
    msg = samples()[sample]
    msg.header.stamp = stamp(i)
    if hasattr(msg, "fillet_id"):
        msg.fillet_id = i
    return msg


def index_of(topic: str, msg) -> int:
    """Inverse of `known` for a decoded rclpy message."""
    t = msg.clock if topic == "/clock" else msg.header.stamp
    return (t.sec - 100) * 10 + round(t.nanosec / 100_000_000)


def _plain(value):
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    if isinstance(value, (list, tuple)) or type(value).__name__ == "array":
        return [_plain(v) for v in value]
    return value


def same(expected, other, where: str = "") -> None:
    """Assert that ``other`` (any decoder's object) has ``expected``'s fields and values."""
    for field in expected.get_fields_and_field_types():
        a = getattr(expected, field)
        b = getattr(other, field)
        here = f"{where}.{field}"
        if hasattr(a, "get_fields_and_field_types"):
            same(a, b, here)
        elif isinstance(a, (list, tuple)) and a and hasattr(a[0], "get_fields_and_field_types"):
            assert len(a) == len(b), here
            for k, (x, y) in enumerate(zip(a, b)):
                same(x, y, f"{here}[{k}]")
        else:
            pa, pb = _plain(a), _plain(b)
            if isinstance(pa, float) and math.isnan(pa):
                assert math.isnan(pb), here
            else:
                assert pa == pb, f"{here}: {str(pa)[:80]} != {str(pb)[:80]}"
