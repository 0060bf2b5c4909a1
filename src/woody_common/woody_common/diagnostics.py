"""Every node's health on ``diagnostics`` (``diagnostic_msgs/DiagnosticArray``), once a second, as
``diagnostic_updater`` publishes it.

A node hands over a function that returns its `Health` now (level, one line, and its figures);
the publisher stamps it with the node's clock (sim time on the line) but fires on the steady
clock, so a line running at a fraction of real time still reports every wall second and a
stalled line keeps reporting that it waits. The topic name is relative (REP 135): under a
namespace it lives there with the line's other topics.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.clock import Clock, ClockType
from rclpy.node import Node

from woody_common import topics

PERIOD_S = 1.0
"""Wall seconds between two reports of one node."""
OK, WARN, ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR
GRADED_UP_TO = "tracks graded up to (sim s)"
"""The grader's figure: the stamp of the latest track message it has graded, to the millisecond. A run that
ends the line on sim time waits for it, so a grader held up still publishes every verdict it owes."""


@dataclass(frozen=True)
class Health:
    """What a node says of itself: a level (`OK`, `WARN`, `ERROR`), one line, and named figures."""

    level: bytes
    message: str
    values: dict[str, object] = field(default_factory=dict)


def _text(value: object) -> str:
    return f"{value:.4g}" if isinstance(value, float) else str(value)


def status_of(node_name: str, health: Health) -> DiagnosticStatus:
    """The `DiagnosticStatus` of a node's health (values as text, floats to 4 significant digits)."""
    return DiagnosticStatus(level=health.level, name=node_name, message=health.message, hardware_id="woody",
                            values=[KeyValue(key=k, value=_text(v)) for k, v in health.values.items()])


class DiagnosticsPublisher:
    """Publishes ``report()`` on ``diagnostics`` every `PERIOD_S` wall seconds for ``node``."""

    def __init__(self, node: Node, report: Callable[[], Health]) -> None:
        self._node = node
        self._report = report
        self._publisher = node.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, 10)
        node.create_timer(PERIOD_S, self.publish, clock=Clock(clock_type=ClockType.STEADY_TIME))

    def publish(self) -> None:
        array = DiagnosticArray(status=[status_of(self._node.get_fully_qualified_name(), self._report())])
        array.header.stamp = self._node.get_clock().now().to_msg()
        self._publisher.publish(array)
