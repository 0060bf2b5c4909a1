"""woody_vision.frame_checks: image decoding (padding, endianness), stamp order, resizes, throttled logs."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from woody_vision.frame_checks import RESIZE_CONFIRM_FRAMES, FrameChecker, FrameError, image_to_array


def image_msg(array: np.ndarray, encoding: str, stamp: float = 0.0, pad: int = 0, bigendian: bool = False,
              width: int | None = None, height: int | None = None):
    rows = np.ascontiguousarray(array)
    row_bytes = int(np.prod(rows.shape[1:])) * rows.itemsize
    raw = np.frombuffer(rows.tobytes(), np.uint8).reshape(rows.shape[0], row_bytes)
    if pad:
        raw = np.concatenate([raw, np.zeros((raw.shape[0], pad), np.uint8)], axis=1)
    sec = int(math.floor(stamp))
    return SimpleNamespace(
        encoding=encoding, height=rows.shape[0] if height is None else height,
        width=rows.shape[1] if width is None else width, step=raw.shape[1], data=raw.tobytes(),
        is_bigendian=int(bigendian),
        header=SimpleNamespace(stamp=SimpleNamespace(sec=sec, nanosec=int(round((stamp - sec) * 1e9)))))


def test_image_to_array_round_trips_and_handles_row_padding_and_endianness():
    depth = np.arange(12, dtype=np.float32).reshape(3, 4)
    assert np.array_equal(image_to_array(image_msg(depth, "32FC1"), "32FC1"), depth)
    assert np.array_equal(image_to_array(image_msg(depth, "32FC1", pad=8), "32FC1"), depth)
    swapped = depth.astype(">f4")
    assert np.array_equal(image_to_array(image_msg(swapped, "32FC1", bigendian=True), "32FC1"), depth)
    rgb = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)
    assert np.array_equal(image_to_array(image_msg(rgb, "rgb8"), "rgb8"), rgb)


def test_image_to_array_rejects_wrong_encoding_and_size():
    depth = np.zeros((3, 4), np.float32)
    with pytest.raises(FrameError, match="encoding"):
        image_to_array(image_msg(depth, "16UC1"), "32FC1")
    with pytest.raises(FrameError):
        image_to_array(image_msg(depth, "32FC1", height=5), "32FC1")  # says 5 rows, holds 3
    with pytest.raises(FrameError):
        image_to_array(image_msg(depth, "32FC1", width=8), "32FC1")  # row step too short for 8 floats
    with pytest.raises(FrameError, match="empty"):
        image_to_array(image_msg(np.zeros((0, 4), np.float32), "32FC1"), "32FC1")
    with pytest.raises(FrameError, match="unsupported"):
        image_to_array(image_msg(depth, "yuv422"), "yuv422")
    msg = image_msg(depth, "32FC1")
    msg.data = msg.data[:-1]
    with pytest.raises(FrameError):
        image_to_array(msg, "32FC1")


class Logger:
    def __init__(self):
        self.lines: list[str] = []

    def warning(self, text: str) -> None:
        self.lines.append(text)


def test_frame_checker_flags_out_of_order_stamps_and_restarts():
    checker = FrameChecker(Logger())
    depth = np.zeros((3, 4), np.float32)
    checker.check(image_msg(depth, "32FC1", 10.0), depth.shape)
    checker.check(image_msg(depth, "32FC1", 10.1), depth.shape)
    with pytest.raises(FrameError, match="out-of-order"):
        checker.check(image_msg(depth, "32FC1", 10.05), depth.shape)
    with pytest.raises(FrameError, match="out-of-order"):
        checker.check(image_msg(depth, "32FC1", 10.1), depth.shape)  # a repeated stamp
    checker.check(image_msg(depth, "32FC1", 10.2), depth.shape)
    assert not checker.restarted
    checker.check(image_msg(depth, "32FC1", 2.0), depth.shape)  # far back in time: a restart (e.g. replay)
    assert checker.restarted
    checker.check(image_msg(depth, "32FC1", 2.1), depth.shape)
    assert not checker.restarted


def test_frame_checker_rejects_a_resize_until_it_persists():
    checker = FrameChecker(Logger())
    small, big = np.zeros((3, 4), np.float32), np.zeros((6, 8), np.float32)
    checker.check(image_msg(small, "32FC1", 0.0), small.shape)
    for i in range(1, RESIZE_CONFIRM_FRAMES):
        with pytest.raises(FrameError, match="size"):
            checker.check(image_msg(big, "32FC1", i * 0.1), big.shape)
    checker.check(image_msg(big, "32FC1", RESIZE_CONFIRM_FRAMES * 0.1), big.shape)
    assert checker.restarted


def test_frame_checker_counts_rejects_and_throttles_the_log():
    logger = Logger()
    checker = FrameChecker(logger, log_period_s=60.0)
    for _ in range(5):
        checker.reject("encoding 'bgr8' where rgb8 is expected; frame skipped")
    checker.reject("empty frame (0 pixels); frame skipped")
    assert checker.rejected == 6 and len(logger.lines) == 2
