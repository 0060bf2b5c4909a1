"""Pairing of depth frames with the colour frame nearest their stamp, as message_filters' ApproximateTime pairs two
streams, but driven by depth: every depth frame comes out exactly once, in order, with a colour frame or with the
reason it has none.

A real camera's colour and depth stamps may differ by up to half a frame, and either may arrive first. A depth frame
is decided once a colour frame stamped at or after it has arrived (a later one can only be farther away), or as
soon as more than ``held`` depth frames wait, so a paced producer waiting for each answer never stalls. A colour
frame is used once. Plain module (no rclpy): stamps are whole nanoseconds, frames any object.
"""

from __future__ import annotations

import bisect
import statistics
from collections import deque
from dataclasses import dataclass
from typing import Any

HELD_DEPTH_FRAMES = 4
"""Depth frames that wait for a colour frame at most: colour may arrive up to four depth frames late (line_sim's own
colour frames reach a subscriber up to four depth frames after their depth frame on a busy 2-core machine)."""
MAX_HELD_DEPTH_FRAMES = 30
"""The most depth frames a pairing holds: a second of a 30 Hz camera (the segmenter's ``color_wait_frames``)."""
COLOR_FRAMES_KEPT = 10
"""Unused colour frames kept (the oldest goes first)."""
INTERVAL_STEPS = 15
"""Recent depth stamp steps whose median is the frame interval (a lost frame's double step does not move it)."""


@dataclass(frozen=True)
class Pair:
    """A depth frame with its colour frame, or with None and why there is none."""

    depth: Any
    color: Any | None
    reason: str = ""


class FramePairing:
    """Nearest-stamp pairing of colour frames to depth frames within a tolerance.

    ``tolerance_s`` 0 means half the depth stream's frame interval (the median of its recent stamp steps); until
    two depth frames have set it only a colour frame of the same stamp pairs without waiting.
    """

    def __init__(self, tolerance_s: float = 0.0, held: int = HELD_DEPTH_FRAMES) -> None:
        self.fixed_ns = round(tolerance_s * 1e9)
        self.held = held
        self.dropped = 0
        self._depths: deque[tuple[int, Any]] = deque()
        self._colors: list[tuple[int, Any]] = []
        self._steps: deque[int] = deque(maxlen=INTERVAL_STEPS)
        self._last_depth: int | None = None

    @property
    def tolerance_ns(self) -> int | None:
        """The largest stamp difference of a pair (ns), or None while the depth frame interval is unknown."""
        if self.fixed_ns:
            return self.fixed_ns
        return round(statistics.median(self._steps) / 2) if self._steps else None

    def add_color(self, stamp_ns: int, frame: Any) -> list[Pair]:
        """Keep a colour frame; the depth frames it decides."""
        bisect.insort(self._colors, (stamp_ns, frame), key=lambda c: c[0])
        if len(self._colors) > COLOR_FRAMES_KEPT:
            del self._colors[0]
        return self._decided()

    def add_depth(self, stamp_ns: int, frame: Any) -> list[Pair]:
        """Queue a depth frame (stamps in order); the depth frames decided now, oldest first."""
        if self._last_depth is not None and stamp_ns > self._last_depth:
            self._steps.append(stamp_ns - self._last_depth)
        self._last_depth = stamp_ns
        self._depths.append((stamp_ns, frame))
        return self._decided()

    def clear(self) -> None:
        """Forget every held frame and the measured interval (the stream restarted)."""
        self._depths.clear()
        self._colors.clear()
        self._steps.clear()
        self._last_depth = None

    def _decided(self) -> list[Pair]:
        out = []
        while self._depths and (pair := self._decide(forced=len(self._depths) > self.held)) is not None:
            out.append(pair)
        return out

    def _decide(self, forced: bool) -> Pair | None:
        """The oldest depth frame's pair, or None while a nearer colour frame may still come."""
        stamp, frame = self._depths[0]
        tolerance = self.tolerance_ns
        nearest = min(range(len(self._colors)), key=lambda i: (abs(self._colors[i][0] - stamp), i), default=None)
        distance = None if nearest is None else abs(self._colors[nearest][0] - stamp)
        reached = bool(self._colors) and self._colors[-1][0] >= stamp and tolerance is not None
        if not (forced or reached or distance == 0):
            return None
        self._depths.popleft()
        if distance is not None and distance <= (tolerance or 0):
            return Pair(frame, self._colors.pop(nearest)[1])
        self.dropped += 1
        within = (f"within ±{tolerance / 1e6:.1f} ms of the depth frame" if tolerance is not None
                  else "with the depth frame's stamp")
        nearest_text = "none received" if distance is None else f"nearest was {distance / 1e6:.1f} ms away"
        return Pair(frame, None, f"no colour frame {within} ({nearest_text})")
