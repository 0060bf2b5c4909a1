"""When line_sim's cameras are due, in sim time."""

from __future__ import annotations

import math

DUE_SLACK = 1e-9
"""A camera is due at a step whose sim time is within this of its frame time (steps are float multiples)."""


class FrameSchedule:
    """A top camera every ``top_period`` and a side camera every ``side_period`` seconds (None: no side camera),
    both from sim time 0."""

    def __init__(self, top_period: float, side_period: float | None) -> None:
        self.top_period, self.side_period = top_period, side_period
        self.next_top = 0.0
        self.next_side = 0.0 if side_period is not None else math.inf

    def due(self, now: float) -> tuple[bool, bool]:
        """Whether the top and the side camera are due at sim time ``now``; each due frame moves its camera's
        next frame time on by one period."""
        top = now + DUE_SLACK >= self.next_top
        side = now + DUE_SLACK >= self.next_side
        if top:
            self.next_top += self.top_period
        if side:
            self.next_side += self.side_period
        return top, side

    @property
    def next_time(self) -> float:
        """Sim time of the next frame of either camera."""
        return min(self.next_top, self.next_side)
