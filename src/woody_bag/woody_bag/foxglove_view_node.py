"""``foxglove_view``: the running line live in Foxglove, over the Foxglove WebSocket protocol (foxglove-sdk).

Parameters (``--ros-args -p name:=value``):

- ``port`` (8765; 0 = any free port, named in the log) and ``host`` (``127.0.0.1``; ``0.0.0.0`` serves
  the network): where Foxglove connects (Open connection → Foxglove WebSocket → ``ws://HOST:PORT``).
- ``image_rate_hz`` (10): the most frames per second (wall time) each image topic sends a client; a
  6-lane line's 30 Hz cameras would otherwise cost the line the CPU the client cannot use anyway.
- ``discovery_period`` (s, 1.0) and ``exclude_regex`` (``/rosout``, ``/parameter_events``, hidden
  topics): which topics of the graph are offered, found again every period.

Every topic whose type is importable is offered as a channel with its ROS 2 schema (``ros2msg``, as
rosbag2 stores it) and CDR messages, as foxglove_bridge offers it, under the names the graph uses. A
topic is subscribed on the ROS side only while a client watches it, so an open view with nothing
watched costs the line only discovery. The line's ``/clock`` is the server's time (Foxglove's clock
runs at the line's pace). Every node's parameters are offered read-only (``<node>.<parameter>``, read
again every few seconds, woody_bag.graph_parameters; a set request is answered with the values
unchanged). Nothing a client sends reaches the line: no client publishing, no parameter changes, no
services.
"""

from __future__ import annotations

import queue
import re
import sys
import time

import foxglove
from foxglove.websocket import Capability, Parameter, ServerListener
from rclpy.clock import Clock, ClockType
from rclpy.node import Node

from woody_bag.graph_parameters import GraphParameters
from woody_bag.qos import subscription_qos
from woody_bag.recorder_node import CLOCK_TYPE, DEFAULT_EXCLUDE, clock_stamp
from woody_bag.schemas import message_class, message_definition
from woody_common.ros_params import check_overrides, declare, run_node, usage

IMAGE_TYPES = {"sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage"}
QUEUE_DEPTH = 10
"""Keep-last depth of a watched topic: a view shows the newest, it never catches up on a backlog."""
TIME_PERIOD_S = 0.1
"""Wall seconds between two broadcasts of the line's time."""


class _Watching(ServerListener):
    """Hands the clients' subscribe and unsubscribe requests to the node's thread (rclpy is not thread-safe) and
    answers parameter requests from the values the node's thread last read."""

    def __init__(self, parameters: GraphParameters) -> None:
        self.requests: queue.SimpleQueue = queue.SimpleQueue()
        self.parameters = parameters

    def on_get_parameters(self, client, param_names: list[str], request_id: str | None = None) -> list[Parameter]:
        values = self.parameters.values
        return [Parameter(name, value=value) for name, value in values.items()
                if value is not None and (not param_names or name in param_names)]

    def on_set_parameters(self, client, parameters: list[Parameter], request_id: str | None = None) -> list[Parameter]:
        """Read-only: the requested parameters with their values unchanged."""
        return self.on_get_parameters(client, [parameter.name for parameter in parameters], request_id)

    def on_subscribe(self, client, channel) -> None:
        self.requests.put((channel.topic, +1))

    def on_unsubscribe(self, client, channel) -> None:
        self.requests.put((channel.topic, -1))


class FoxgloveView(Node):
    """Offers the graph's topics to Foxglove clients and forwards the watched ones."""

    def __init__(self) -> None:
        super().__init__("foxglove_view")
        port = declare(self, "port", 8765, "WebSocket port (0 = any free port)", 0, 65535)
        host = declare(self, "host", "127.0.0.1", "address to serve on (0.0.0.0: every interface)")
        self.image_period = 1.0 / declare(self, "image_rate_hz", 10.0, "most frames a second per image topic",
                                          0.1, 1000.0)
        period = declare(self, "discovery_period", 1.0, "seconds between searches for new topics", 0.05, 60.0)
        self.exclude = re.compile(declare(self, "exclude_regex", DEFAULT_EXCLUDE, "never offer matching topics"))
        check_overrides(self)
        self.parameters = GraphParameters(self)
        self.watching = _Watching(self.parameters)
        self.server = foxglove.start_server(name="woody", host=host, port=port,
                                            capabilities=[Capability.Time, Capability.Parameters],
                                            server_listener=self.watching)
        self.channels: dict[str, tuple[foxglove.Channel, str]] = {}
        self.watchers: dict[str, int] = {}
        self.forwarding: dict[str, object] = {}
        self._time_sent = 0.0
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(period, self.discover, clock=steady)
        self.create_timer(0.02, self.follow_clients, clock=steady)
        self.discover()
        self.get_logger().info(f"Foxglove view on ws://{host}:{self.server.port} (images at most "
                               f"{1.0 / self.image_period:g} Hz per topic)")

    def discover(self) -> None:
        """Offer every new topic of an importable type as a channel, then forward each wanted topic (watched, or
        the clock) whose first publisher has come: until then its QoS is not known."""
        for topic, types in self.get_topic_names_and_types():
            if topic in self.channels or len(types) != 1 or self.exclude.search(topic):
                continue
            try:
                message_class(types[0])
                schema = foxglove.Schema(name=types[0], encoding="ros2msg", data=message_definition(types[0]).encode())
            except LookupError:
                continue
            self.channels[topic] = (foxglove.Channel(topic, schema=schema, message_encoding="cdr"), types[0])
        for topic in [t for t in self.channels if self._wanted(t) and t not in self.forwarding]:
            self._subscribe(topic)
        self.parameters.refresh()

    def _wanted(self, topic: str) -> bool:
        """A topic is forwarded while a client watches it; the clock always (it is the server's time)."""
        return self.watchers.get(topic, 0) > 0 or self.channels[topic][1] == CLOCK_TYPE

    def follow_clients(self) -> None:
        """Subscribe a topic when its first client watches it, unsubscribe when its last one leaves."""
        while True:
            try:
                topic, change = self.watching.requests.get_nowait()
            except queue.Empty:
                return
            self.watchers[topic] = max(0, self.watchers.get(topic, 0) + change)
            if topic not in self.channels:
                continue
            if self._wanted(topic) and topic not in self.forwarding:
                self._subscribe(topic)
            elif not self._wanted(topic) and topic in self.forwarding:
                self.destroy_subscription(self.forwarding.pop(topic))

    def _subscribe(self, topic: str) -> None:
        channel, type_name = self.channels[topic]
        publishers = self.get_publishers_info_by_topic(topic)
        if not publishers:
            return  # only subscribers so far: discover() tries again
        clock, last = self.get_clock(), [0.0]

        def forward(data: bytes) -> None:
            if type_name in IMAGE_TYPES:
                now = time.monotonic()
                if now - last[0] < self.image_period:
                    return
                last[0] = now
            if type_name == CLOCK_TYPE:
                self._broadcast_time(data)
            channel.log(data, log_time=clock.now().nanoseconds)

        self.forwarding[topic] = self.create_subscription(
            message_class(type_name), topic, forward, subscription_qos(publishers, QUEUE_DEPTH), raw=True)

    def _broadcast_time(self, data: bytes) -> None:
        now = time.monotonic()
        if now - self._time_sent >= TIME_PERIOD_S:
            self._time_sent = now
            sec, nanosec = clock_stamp(data)
            self.server.broadcast_time(sec * 1_000_000_000 + nanosec)

    def close(self) -> None:
        self.server.stop()
        self.get_logger().info(f"Foxglove view closed ({len(self.channels)} topics offered)")


def main(args: list[str] | None = None) -> int:
    """Serve the line to Foxglove until SIGINT/SIGTERM. Exit code 0, 2 on bad parameters."""
    help_text = usage("foxglove_view").splitlines()[0] + "\n" + __doc__.split("\n\n", 1)[1]
    return run_node("foxglove_view", FoxgloveView, args, help_text=help_text)


if __name__ == "__main__":
    sys.exit(main())
