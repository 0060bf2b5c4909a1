"""woody_common.images: numpy frames into sensor_msgs/Image, byte for byte."""

import array

import numpy as np
import pytest
from std_msgs.msg import Header

from woody_common.images import image_message


@pytest.mark.parametrize("pixels,encoding", [
    (np.arange(4 * 5 * 3, dtype=np.uint8).reshape(4, 5, 3), "rgb8"),
    (np.linspace(0.1, 2.0, 4 * 5, dtype=np.float32).reshape(4, 5), "32FC1"),
    (np.arange(4 * 5, dtype=np.uint16).reshape(4, 5) * 1000, "16UC1"),
])
def test_the_message_holds_the_frame_bytes_size_step_and_encoding(pixels, encoding):
    header = Header(frame_id="top_camera_optical_frame")
    msg = image_message(pixels, encoding, header)
    assert (msg.height, msg.width, msg.step, msg.encoding) == (4, 5, pixels.strides[0], encoding)
    assert msg.header.frame_id == "top_camera_optical_frame" and msg.is_bigendian == 0
    assert isinstance(msg.data, array.array) and msg.data.tobytes() == pixels.tobytes()


def test_a_strided_view_is_packed_and_later_changes_to_the_frame_do_not_reach_the_message():
    frame = np.arange(6 * 8 * 3, dtype=np.uint8).reshape(6, 8, 3)
    view = frame[::2, 1:7]
    msg = image_message(view, "rgb8")
    assert (msg.height, msg.width, msg.step) == (3, 6, 18)
    expected = view.tobytes()
    frame[:] = 0
    assert msg.data.tobytes() == expected
