"""woody_vision.image_qos: the image_qos parameter picks best effort (default) or reliable; others refused.

A stand-in node answers the declaration (no rclpy context, no graph); the node tests start the real ones.
"""

from __future__ import annotations

from types import SimpleNamespace

import pytest
from rclpy.qos import HistoryPolicy, ReliabilityPolicy

from woody_vision.image_qos import CHOICES, declare_image_qos


class StandIn:
    """What declare_image_qos asks of a node: declare_parameter, answered with the override or the default."""

    def __init__(self, value: str | None = None) -> None:
        self.value, self.declared = value, {}

    def declare_parameter(self, name, default, descriptor):
        self.declared[name] = descriptor
        return SimpleNamespace(value=default if self.value is None else self.value)


def test_default_is_sensor_data():
    node = StandIn()
    profile = declare_image_qos(node, depth=5)
    assert profile.reliability == ReliabilityPolicy.BEST_EFFORT
    assert (profile.history, profile.depth) == (HistoryPolicy.KEEP_LAST, 5)
    assert node.declared["image_qos"].read_only and "sensor_data" in node.declared["image_qos"].description


def test_reliable_on_request():
    assert declare_image_qos(StandIn("reliable")).reliability == ReliabilityPolicy.RELIABLE
    assert set(CHOICES) == {"sensor_data", "reliable"}


def test_an_unknown_choice_is_refused_with_the_choices():
    with pytest.raises(ValueError, match="sensor_data, reliable"):
        declare_image_qos(StandIn("fast"))
