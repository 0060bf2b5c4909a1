"""The QoS the line's results are offered with: the grader's verdicts and side metrics, the gate's commands."""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

RESULTS_DEPTH = 100
"""Results kept for a subscriber: the reliable link's queue, and what one that matches late still gets."""


def results_qos() -> QoSProfile:
    """Reliable and transient-local (latched), RESULTS_DEPTH deep. A subscriber that asks for transient-local
    gets the results published before it matched: a recorder that found the grader's topics only after its
    first verdicts (the grader was slow to start, or stopped a moment) still records them, and ``woody run``'s
    tables, built from the bag, hear every verdict. A volatile subscriber (a reject gate) hears only new ones."""
    return QoSProfile(depth=RESULTS_DEPTH, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)
