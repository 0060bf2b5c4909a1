"""woody_common.images: numpy frames into serialized sensor_msgs/Image, field for field."""

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import Image
from std_msgs.msg import Header

from woody_common.images import serialized_image


@pytest.mark.parametrize("pixels,encoding", [
    (np.arange(4 * 5 * 3, dtype=np.uint8).reshape(4, 5, 3), "rgb8"),
    (np.linspace(0.1, 2.0, 4 * 5, dtype=np.float32).reshape(4, 5), "32FC1"),
    (np.arange(4 * 5, dtype=np.uint16).reshape(4, 5) * 1000, "16UC1"),
])
@pytest.mark.parametrize("frame_id", ["", "a", "ab", "abc", "top_camera_optical_frame"])  # every alignment
def test_the_bytes_are_the_serialized_message_with_the_frame_bytes_size_step_and_encoding(pixels, encoding, frame_id):
    header = Header(frame_id=frame_id, stamp=Time(sec=12, nanosec=345_000_000))
    expected = Image(header=header, height=4, width=5, encoding=encoding, step=pixels.strides[0],
                     data=pixels.tobytes())
    data = serialized_image(pixels, encoding, header)
    assert len(data) == len(serialize_message(expected))  # the same bytes but the padding, which CDR leaves unset
    assert deserialize_message(data, Image) == expected


def test_a_strided_view_is_packed_and_later_changes_to_the_frame_do_not_reach_the_bytes():
    frame = np.arange(6 * 8 * 3, dtype=np.uint8).reshape(6, 8, 3)
    view = frame[::2, 1:7]
    data = serialized_image(view, "rgb8")
    expected = view.tobytes()
    frame[:] = 0
    msg = deserialize_message(data, Image)
    assert (msg.height, msg.width, msg.step) == (3, 6, 18) and msg.data.tobytes() == expected
