"""Keeping a free-running simulation within reach of its slowest consumer (no rclpy).

line_sim can now produce frames faster than the vision graph takes them on a
busy machine; camera topics keep only the last few frames, so the surplus was
silently dropped, tracks broke up and fillets lost their verdicts. The
segmenter answers every depth frame with one /vision/tracks message carrying
the frame's stamp, which acknowledges it: the simulation holds while the
newest acknowledged stamp lags more than ``max_lead_s`` behind. A consumer that
stops answering does not hang the line: after ``stall_s`` of wall time the
hold gives up until the consumer answers again. A consumer that has not
answered at all yet is still starting (imports, DDS discovery, a loaded
machine), so before its first answer the hold waits ``start_s`` instead: giving
up early then let the line run ahead unseen and its first fillets went
unscored.
"""

from __future__ import annotations


class LeadLimiter:
    """Acknowledged sim time of the consumer, and whether the producer must wait for it."""

    def __init__(self, max_lead_s: float, stall_s: float = 5.0, start_s: float = 60.0) -> None:
        if max_lead_s <= 0 or stall_s <= 0 or start_s <= 0:
            raise ValueError(f"max_lead_s, stall_s and start_s must be > 0, got {max_lead_s}, {stall_s}, {start_s}")
        self.max_lead_s = float(max_lead_s)
        self.stall_s = float(stall_s)
        self.start_s = float(start_s)
        self.acked = 0.0  # sim time starts at 0: the first max_lead_s go unacknowledged
        self.answered = False
        self.stalls = 0
        self._stalled = False

    def ack(self, stamp: float) -> None:
        """The consumer has taken the frame of sim time ``stamp``."""
        self.acked = max(self.acked, float(stamp))
        self.answered = True
        self._stalled = False

    def must_wait(self, now: float, waited_s: float) -> bool:
        """Whether a frame at sim time ``now`` must wait, having waited ``waited_s`` wall seconds so far."""
        if self._stalled or now - self.acked <= self.max_lead_s + 1e-9:
            return False
        if waited_s >= (self.stall_s if self.answered else self.start_s):
            self.stalls += 1
            self._stalled = True
            return False
        return True
