"""Keeping a free-running simulation within reach of its slowest consumer (no rclpy).

line_sim can now produce frames faster than the vision graph takes them on a
busy machine; camera topics keep only the last few frames, so the surplus was
silently dropped, tracks broke up and fillets lost their verdicts. The
segmenter answers every depth frame with one /vision/tracks message carrying
the frame's stamp, which acknowledges it: the simulation holds while the
newest acknowledged stamp lags more than ``max_lead_s`` behind.

A held frame can be lost in transit (best-effort images) or while the
consumer is held up, and then no answer comes for it: every ``probe_s`` of
holding one more frame goes out, so an answer can come and the line moves on
in step. A consumer that stays silent does not hang the line: after
``stall_s`` of silence the hold gives up until it answers again. One that has
not answered at all yet is still starting (imports, DDS discovery, a loaded
machine) and is given ``start_s``; giving up after the shorter time let the
line run ahead unseen and its first fillets went unscored.
"""

from __future__ import annotations

import time
from collections.abc import Callable


class LeadLimiter:
    """Acknowledged sim time of the consumer, and whether the producer must wait for it."""

    def __init__(self, max_lead_s: float, stall_s: float = 10.0, start_s: float = 60.0, probe_s: float = 0.5,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if min(max_lead_s, stall_s, start_s, probe_s) <= 0:
            raise ValueError(f"max_lead_s, stall_s, start_s and probe_s must be > 0, got {max_lead_s}, {stall_s}, "
                             f"{start_s}, {probe_s}")
        self.max_lead_s, self.stall_s, self.start_s, self.probe_s = (
            float(max_lead_s), float(stall_s), float(start_s), float(probe_s))
        self.acked = 0.0  # sim time starts at 0: the first max_lead_s go unacknowledged
        self.answered = False
        self.stalls = 0
        self._stalled = False
        self._clock = clock
        self._last_answer = self._last_release = clock()

    def ack(self, stamp: float) -> None:
        """The consumer has taken the frame of sim time ``stamp``."""
        self.acked = max(self.acked, float(stamp))
        self.answered = True
        self._stalled = False
        self._last_answer = self._clock()

    def must_wait(self, now: float) -> bool:
        """Whether the frame at sim time ``now`` must wait (call again while it does)."""
        wall = self._clock()
        if self._stalled or now - self.acked <= self.max_lead_s + 1e-9:
            self._last_release = wall
            return False
        if wall - self._last_answer >= (self.stall_s if self.answered else self.start_s):
            self.stalls += 1
            self._stalled = True
            return False
        if wall - self._last_release >= self.probe_s:
            self._last_release = wall
            return False
        return True
