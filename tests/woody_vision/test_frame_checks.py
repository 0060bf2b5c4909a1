"""woody_vision.frame_checks: image decoding (padding, endianness), stamp order, resizes, throttled logs."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from woody_vision.frame_checks import (
    GAP_FRAMES,
    RESIZE_CONFIRM_FRAMES,
    RESTART_JUMP_S,
    FrameChecker,
    FrameError,
    SimTimeWatch,
    frame_interval,
    image_to_array,
    is_gap,
)


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


def test_a_step_of_more_than_gap_frames_intervals_is_a_gap():
    assert frame_interval([0.0, 0.5, 1.0, 1.0167, 1.0333, 1.1]) == pytest.approx(0.0166, abs=1e-3)
    assert math.isinf(frame_interval([2.0])) and math.isinf(frame_interval([1.0, 1.0]))
    assert not is_gap(2 * 0.02, 0.02) and is_gap(3 * 0.02, 0.02)  # one lost frame is tolerated, two are not
    assert not is_gap(GAP_FRAMES * 0.02, 0.02) and not is_gap(10.0, math.inf)


def test_sim_time_going_back_is_noticed_once_per_jump_whichever_source_shows_it_first():
    watch = SimTimeWatch()
    assert not any(watch.went_back(source, t) for t in (1.0, 2.0, 3.0) for source in ("depth", "side"))
    assert not watch.went_back("side", 3.0 - 0.9 * RESTART_JUMP_S), "a stray late frame is no jump"
    assert watch.clock_current(12.0), "a clock ahead of lagging frames tells the time"
    assert watch.went_back("depth", 0.2)  # a replay started again
    assert not watch.went_back("side", 0.2), "the same jump on another stream counts once"
    assert not watch.clock_current(12.0), "the clock has not jumped yet: its time is gone"
    assert not watch.clock_went_back(0.25) and watch.clock_current(0.25)
    assert not watch.went_back("depth", 0.3) and not watch.went_back("side", 0.3)


def test_a_clock_jump_counts_while_the_streams_are_still_ahead_of_it():
    watch = SimTimeWatch()
    watch.went_back("tracks", 20.0)
    assert watch.clock_went_back(0.5), "the clock jumped first"
    assert not watch.went_back("tracks", 0.6), "the streams follow: no second reset"
    assert not SimTimeWatch().clock_went_back(0.0), "nothing seen yet: nothing to forget"
