"""Which side-camera frames are worth rendering and publishing (no rclpy).

A side frame of an empty view is the static background: at 60 Hz and
960×696 rgb8 it costs ~120 MB/s of copying and DDS traffic for nothing. The
gate passes every due frame while a fillet of the watched lane may be in view
and for ``tail_frames`` after the view empties (the grader's side tracker ends
a passage after a few frames without its silhouette), and otherwise one frame
per ``idle_period_s``, so a consumer that joins late still learns the
background.
"""

from __future__ import annotations

DEFAULT_TAIL_FRAMES = 10
"""Frames still passed after the view empties (the side tracker needs 3 to end a passage)."""


class SideFrameGate:
    """Decides per due side frame whether to render it."""

    def __init__(self, idle_period_s: float, tail_frames: int = DEFAULT_TAIL_FRAMES) -> None:
        if idle_period_s <= 0 or tail_frames < 0:
            raise ValueError(f"idle_period_s must be > 0 and tail_frames >= 0, got {idle_period_s}, {tail_frames}")
        self.idle_period_s = float(idle_period_s)
        self.tail_frames = int(tail_frames)
        self._empty = 0  # consecutive due frames with an empty view (the first frames pass: the background)
        self._next_idle = 0.0

    def take(self, occupied: bool, now: float) -> bool:
        """Whether the frame due at sim time ``now`` is rendered; ``occupied``: a fillet may be in view."""
        self._empty = 0 if occupied else self._empty + 1
        if occupied or self._empty <= self.tail_frames or now + 1e-9 >= self._next_idle:
            self._next_idle = now + self.idle_period_s
            return True
        return False
