"""Defensive decoding of camera frames: wrong encoding, size, empty or out-of-order frames.

Plain module (duck-typed on sensor_msgs/Image fields, no rclpy import) so the
same checks guard the nodes and the tests. A bad frame raises FrameError with
one line naming the topic problem; FrameChecker logs it (throttled) and the
caller skips the frame.
"""

from __future__ import annotations

import time

import numpy as np

from woody_common.stamps import stamp_to_seconds

ENCODINGS = {"rgb8": (np.uint8, 3), "bgr8": (np.uint8, 3), "mono8": (np.uint8, 1), "32FC1": (np.float32, 1),
             "16UC1": (np.uint16, 1)}
"""REP 118 encodings the project reads, with their dtype and channel count."""

RESTART_JUMP_S = 1.0
"""A stamp that goes back by more than this is a camera (or replay) restart, not a stray frame."""

RESIZE_CONFIRM_FRAMES = 30
"""A new image size becomes the size once this many frames in a row carry it (a camera restarted differently)."""


class FrameError(ValueError):
    """A frame that cannot be used; the message is one line saying why."""


def image_to_array(msg, encoding: str) -> np.ndarray:
    """A (H, W) or (H, W, C) numpy view of an Image's data, after checking encoding and size."""
    if msg.encoding != encoding:
        raise FrameError(f"encoding '{msg.encoding}' where {encoding} is expected; frame skipped")
    if encoding not in ENCODINGS:
        raise FrameError(f"unsupported encoding '{encoding}'")
    if msg.width == 0 or msg.height == 0:
        raise FrameError("empty frame (0 pixels); frame skipped")
    dtype, channels = ENCODINGS[encoding]
    itemsize = np.dtype(dtype).itemsize
    row = msg.width * channels * itemsize
    if msg.step < row or len(msg.data) < msg.step * msg.height:
        raise FrameError(f"frame data of {len(msg.data)} bytes (step {msg.step}) does not hold "
                         f"{msg.width}x{msg.height} {encoding}; frame skipped")
    raw = np.frombuffer(msg.data, dtype=np.uint8, count=msg.step * msg.height).reshape(msg.height, msg.step)
    pixels = raw[:, :row].view(dtype)
    if msg.is_bigendian != (np.little_endian is False) and itemsize > 1:
        pixels = pixels.byteswap()
    return pixels.reshape(msg.height, msg.width, channels) if channels > 1 else pixels.reshape(msg.height, msg.width)


class FrameChecker:
    """Tracks stamps and sizes of one camera stream and logs bad frames without flooding the log."""

    def __init__(self, logger, log_period_s: float = 2.0) -> None:
        self.logger = logger
        self.log_period_s = log_period_s
        self.rejected = 0
        self.restarted = False
        self._last_stamp: float | None = None
        self._shape: tuple[int, ...] | None = None
        self._new_shape: tuple[int, ...] | None = None
        self._new_shape_count = 0
        self._last_log: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}

    def reset(self) -> None:
        self._last_stamp = None
        self._shape = None

    def check(self, msg, shape: tuple[int, ...]) -> None:
        """Raise FrameError for an out-of-order or resized frame; set ``restarted`` on a stream restart."""
        self.restarted = False
        stamp = stamp_to_seconds(msg.header.stamp)
        if self._shape is not None and shape != self._shape:
            if shape != self._new_shape:
                self._new_shape, self._new_shape_count = shape, 0
            self._new_shape_count += 1
            if self._new_shape_count < RESIZE_CONFIRM_FRAMES:
                raise FrameError(f"image size {shape[1]}x{shape[0]} differs from the stream's "
                                 f"{self._shape[1]}x{self._shape[0]}; frame skipped")
            self.restarted = True
        elif self._last_stamp is not None and stamp <= self._last_stamp:
            if self._last_stamp - stamp <= RESTART_JUMP_S:
                raise FrameError(f"out-of-order stamp {stamp:.3f} s after {self._last_stamp:.3f} s; frame skipped")
            self.restarted = True
        self._shape = shape
        self._new_shape, self._new_shape_count = None, 0
        self._last_stamp = stamp

    def reject(self, reason: str) -> None:
        """Count a skipped frame and log its reason (at most once per period per reason)."""
        self.rejected += 1
        key = reason.split(";")[0][:40]
        now = time.monotonic()
        if now - self._last_log.get(key, -1e9) >= self.log_period_s:
            extra = self._suppressed.pop(key, 0)
            self.logger.warning(reason + (f" (and {extra} more like it)" if extra else ""))
            self._last_log[key] = now
        else:
            self._suppressed[key] = self._suppressed.get(key, 0) + 1
