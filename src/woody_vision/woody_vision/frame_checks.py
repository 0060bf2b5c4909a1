"""Defensive decoding of camera frames: wrong encoding, size, empty or out-of-order frames; gaps and sim time
going back.

Plain module (duck-typed on sensor_msgs/Image fields; rclpy only inside
:func:`watch_clock`) so the same checks guard the nodes, the measuring modules
and the tests. A bad frame raises FrameError with
one line naming the topic problem; FrameChecker logs it (throttled) and the
caller skips the frame. A measurement over several frames (a Φ window, a side
passage) is published only if no step between its frames is a gap
(:func:`is_gap`); a node forgets its per-fillet state when sim time goes back
(:class:`SimTimeWatch`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from woody_common.stamps import stamp_to_seconds

ENCODINGS = {"rgb8": (np.uint8, 3), "bgr8": (np.uint8, 3), "mono8": (np.uint8, 1), "32FC1": (np.float32, 1),
             "16UC1": (np.uint16, 1)}
"""REP 118 encodings the project reads, with their dtype and channel count."""

RESTART_JUMP_S = 1.0
"""A stamp that goes back by more than this is a camera (or replay) restart, not a stray frame."""

GAP_FRAMES = 2.5
"""A step between consecutive frames longer than this many frame intervals is a gap: one lost frame (a step of
two intervals) is tolerated, two or more in a row are not. What a fillet's frames measure across a gap (the
maximum Φ_t of a window, the minimum MDM of a side passage, a window that closes late) is not published."""

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


def frame_interval(stamps) -> float:
    """The stream's frame interval: the smallest positive step between consecutive ``stamps`` (inf when none)."""
    steps = np.diff(np.asarray(stamps, dtype=float))
    steps = steps[steps > 0]
    return float(steps.min()) if steps.size else math.inf


def is_gap(step: float, interval: float) -> bool:
    """Whether a step between two frames of a stream with this frame interval lost more than one frame."""
    return step > GAP_FRAMES * interval


class SimTimeWatch:
    """Notices sim time going back on a node's time sources: the stamps of each stream it receives, and /clock.

    Each stream is compared with its own latest stamp (a lagging subscriber's
    frames are older than the newest /clock, and that is no jump). A jump on
    one source starts every source over, so the same jump arriving later on
    another one does not count twice; a /clock jump counts only while some
    stream is still ahead of it. Between a jump seen on a stream and the same
    jump on /clock, the clock still tells the time that is gone
    (:meth:`clock_current`).
    """

    def __init__(self, tolerance_s: float = RESTART_JUMP_S) -> None:
        self.tolerance_s = tolerance_s
        self._latest: dict[str, float] = {}
        self._clock_stale = False

    def went_back(self, source: str, stamp: float) -> bool:
        """Record ``stamp`` (s) of stream ``source``; True when it lies more than the tolerance before the
        stream's latest."""
        last = self._latest.get(source)
        if last is not None and stamp < last - self.tolerance_s:
            self._latest = {source: stamp}
            self._clock_stale = True
            return True
        self._latest[source] = stamp if last is None else max(last, stamp)
        return False

    def clock_went_back(self, now: float) -> bool:
        """/clock jumped back to ``now`` (s): True when a stream's latest stamp lies more than the tolerance ahead
        of it (a jump no stream has shown yet)."""
        self._clock_stale = False
        if any(last > now + self.tolerance_s for last in self._latest.values()):
            self._latest = {}
            return True
        return False

    def clock_current(self, now: float) -> bool:
        """Whether /clock at ``now`` (s) tells the streams' time: not after they jumped back while it did not (yet)."""
        if self._clock_stale and now <= max(self._latest.values(), default=now) + self.tolerance_s:
            self._clock_stale = False
        return not self._clock_stale


def watch_clock(node, watch: SimTimeWatch, forget: Callable[[str], None]):
    """Call ``forget(why)`` when the node's /clock jumps back past what its streams have shown; returns the
    jump handle, which the node keeps (the callback lives as long as it)."""
    from rclpy.clock import JumpThreshold  # here, not at the top: the measuring modules import this one without ROS
    from rclpy.duration import Duration

    def jumped(jump) -> None:
        now = node.get_clock().now().nanoseconds * 1e-9
        if watch.clock_went_back(now):
            forget(f"/clock went back by {-jump.delta.nanoseconds * 1e-9:.2f} s to {now:.2f} s")

    every_step_back = JumpThreshold(min_forward=None, min_backward=Duration(nanoseconds=-1), on_clock_change=False)
    return node.get_clock().create_jump_callback(every_step_back, post_callback=jumped)


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
